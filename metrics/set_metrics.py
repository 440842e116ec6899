"""Set-level metric plugins: a generated set S scored against a reference set R at once.

`domain = "set"`: computed from the distance matrices of R and S over one distance
(`compute(d_rr, d_ss, d_rs)`; MMD, COV, 1-NNA of `distributional`); `domain = "image_set"`:
computed from the two sets' rendered images (`compute(images_r, images_s)`; FID). The
generation harness calls every set metric of `harness.metrics` through these classes, so a
third party registers another the same way. A metric whose class sets `uses_device = True`
is also given the job's device (`compute(..., device=...)`, a torch.device; the CPU where
the job names none) for its own heavy work (FID: the network's feature extraction).
"""

from __future__ import annotations

from brdfbench.protocols.metric import ImageSetMetric, SetMetric

from . import distributional as dist
from .fid import fid


class MMD(SetMetric):
    """Minimum matching distance: mean over R of the distance to the nearest sample (fidelity)."""

    unit = "distance"

    def unit_for(self, distance_unit: str) -> str:
        return distance_unit

    def compute(self, d_rr, d_ss, d_rs) -> float:
        return dist.mmd(d_rs)


class COV(SetMetric):
    """Coverage: the share of R that is some sample's nearest reference member (diversity), in %."""

    unit = "%"
    higher_is_better = True

    def compute(self, d_rr, d_ss, d_rs) -> float:
        return 100.0 * dist.cov(d_rs)


class OneNNA(SetMetric):
    """Leave-one-out 1-NN accuracy over R ∪ S, in % (50 is ideal; lower is better down to it)."""

    unit = "% (ideal 50)"

    def compute(self, d_rr, d_ss, d_rs) -> float:
        return 100.0 * dist.one_nna(d_rr, d_ss, d_rs)


class FID(ImageSetMetric):
    """Fréchet Inception distance between the rendered images of R and S (standard InceptionV3)."""

    unit = "1"
    uses_device = True

    def compute(self, images_r, images_s, *, device=None) -> float:
        """`device` (None: the CPU): where InceptionV3 extracts the features; the distance
        itself is fp64 on the CPU."""
        return float(fid(images_r, images_s, device=device))
