"""Representations that fit side by side (`fits_in_parallel`) and fail in a fit helper:
one raises for one material, one kills its helper process, one records where it fitted."""

from __future__ import annotations

import os
import signal

from brdfbench_representations.lambert import Lambert

#: The material these plugins fail on.
VICTIM = "synth-metal-chrome-01"


class WhereFitted(Lambert):
    """Lambert fitted in a helper; its fit loss is the id of the process that fitted it."""

    fits_in_parallel = True

    def fit(self, target, *, seed=0):
        super().fit(target, seed=seed)
        self.pid = os.getpid()
        return self

    def metadata(self):
        return {"fit_loss": float(getattr(self, "pid", 0))}


class RaisesOnOne(Lambert):
    """Lambert fitted side by side whose fit raises for VICTIM."""

    fits_in_parallel = True

    def fit(self, target, *, seed=0):
        if target.name == VICTIM:
            raise ValueError(f"cannot fit {target.name}")
        return super().fit(target, seed=seed)


class KillsItsHelper(Lambert):
    """Lambert fitted side by side whose fit ends its process with SIGSEGV on VICTIM."""

    fits_in_parallel = True

    def fit(self, target, *, seed=0):
        if target.name == VICTIM:
            os.kill(os.getpid(), signal.SIGSEGV)
        return super().fit(target, seed=seed)


class HangsOnOne(Lambert):
    """Lambert fitted side by side whose fit on VICTIM writes its process id to the file
    $BRDFBENCH_TEST_PID_FILE and then never returns."""

    fits_in_parallel = True

    def fit(self, target, *, seed=0):
        if target.name == VICTIM:
            with open(os.environ["BRDFBENCH_TEST_PID_FILE"], "w") as f:
                f.write(str(os.getpid()))
            while True:
                signal.pause()
        return super().fit(target, seed=seed)
