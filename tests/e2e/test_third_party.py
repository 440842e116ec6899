"""A third-party distribution registers a representation through an entry point only,
and is then listed, certified by the conformance kit and benchmarked by the CLI."""

import os
import subprocess
import sys
import textwrap

import pytest

PLUGIN = '''
import math
import torch
from brdfbench.protocols.representation import Representation
from brdfbench.plugins.specs import RepresentationSpec
from brdfbench.state_checks import expect_tensor


class Phong(Representation):
    """Normalised modified Phong: rho_d/pi + rho_s (n+2)/(2 pi) cos^n(alpha), alpha to the mirror direction."""
    tags = frozenset({"fittable", "reciprocal", "isotropic"})

    def __init__(self, exponent: float = 20.0):
        super().__init__(exponent=exponent)
        self.kd = torch.full((3,), 0.3, dtype=torch.float64)
        self.ks = torch.full((3,), 0.1, dtype=torch.float64)

    def fit(self, target, *, seed=0):
        values = torch.from_numpy(target.table.values).clamp_min(0).reshape(3, -1)
        self.kd = values.median(dim=1).values * math.pi
        return self

    def _eval(self, wi, wo):
        mirror = torch.stack((-wi[:, 0], -wi[:, 1], wi[:, 2]), dim=-1)
        c = (mirror * wo).sum(-1).clamp(0, 1) ** self.params["exponent"]
        n = self.params["exponent"]
        return (self.kd / math.pi + self.ks * (n + 2) / (2 * math.pi) * c[:, None].double()).to(wi.dtype)

    def state_dict(self):
        return {"kd": self.kd, "ks": self.ks}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)  # a model file is data from anywhere: its tensors are checked
        model.kd, model.ks = (expect_tensor(tensors, k, (3,), owner="acme_phong model", nonneg=True) for k in ("kd", "ks"))
        return model


SPEC = RepresentationSpec(
    name="acme_phong", description="ACME's normalised Phong (third-party test plugin)",
    target="acme_brdf:Phong", tags=frozenset({"fittable", "reciprocal", "isotropic"}),
)
'''


@pytest.fixture(scope="module")
def third_party_path(tmp_path_factory):
    root = tmp_path_factory.mktemp("site")
    (root / "acme_brdf.py").write_text(textwrap.dedent(PLUGIN))
    info = root / "acme_brdf-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: acme-brdf\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[brdfbench.representations]\nacme_phong = acme_brdf:SPEC\n")
    return root


def _run(args, path, cwd):
    env = dict(os.environ, PYTHONPATH=f"{path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    return subprocess.run([sys.executable, "-m", "brdfbench.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def test_listed_certified_and_benchmarked(third_party_path, tmp_path):
    listed = _run(["list", "representations"], third_party_path, tmp_path)
    assert "acme_phong" in listed.stdout and "ACME" in listed.stdout

    checked = _run(["check", "acme_phong", "--pairs", "70000"], third_party_path, tmp_path)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert "failed" not in checked.stdout and "save_load_roundtrip" in checked.stdout

    bench = _run(["representation=custom", "representation.name=acme_phong",
                  "+representation.params.exponent=50", "dataset.params.size=small", "harness=quick",
                  "limit=2", f"results_dir={tmp_path}/res"], third_party_path, tmp_path)
    assert bench.returncode == 0, bench.stderr
    assert "Launching 1 jobs" in bench.stdout + bench.stderr
    assert "`acme_phong`" in (tmp_path / "res" / "leaderboard.md").read_text()
