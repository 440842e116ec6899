"""The built-in BRDF-space metrics, as `brdfbench.protocols.metric.Metric` classes: the mean
of a functional twin's per-element terms (`functional`), streamed over chunks.

`Metric` is re-exported here for plugins written against this module before the protocol
moved into the core.
"""

from __future__ import annotations

from brdfbench.protocols.metric import Metric

from . import functional as F

__all__ = ["Metric", "L1", "L1Log", "L1LogCos", "HDRMAE", "HDRRMSE"]


class L1(Metric):
    terms = staticmethod(F.l1_terms)
    unit = "1/sr"


class L1Log(Metric):
    terms = staticmethod(F.l1_log_terms)
    unit = "log(1+1/sr)"


class L1LogCos(Metric):
    terms = staticmethod(F.l1_log_cos_terms)
    unit = "log(1+1/sr)"


class HDRMAE(Metric):
    terms = staticmethod(F.l1_terms)
    unit = "1/sr"
    domain = "random_pairs"


class HDRRMSE(Metric):
    terms = staticmethod(F.squared_error_terms)
    unit = "1/sr"
    domain = "random_pairs"

    def _finish(self, mean: float) -> float:
        return mean ** 0.5
