"""A third-party harness registered through entry points only (and its config group through
`brdfbench.conf`) runs through the CLI: typed keys checked, its rows stored and reported."""

import os
import subprocess
import sys
import textwrap

import pytest

from brdfbench.store.sqlite import ResultsStore

HARNESS = '''
from dataclasses import dataclass, field

import torch

from brdfbench.harness import Harness, HarnessConfig, Measurement
from brdfbench.plugins.specs import HarnessSpec


@dataclass(frozen=True)
class AlbedoConfig(HarnessConfig):
    kind: str = "acme_albedo"
    n_dirs: int = field(default=64, metadata={"min": 1})


class AlbedoHarness(Harness):
    """Mean BRDF value at normal incidence over n_dirs outgoing directions (a toy measure)."""

    name = "acme_albedo"
    Config = AlbedoConfig

    def measure(self, model, material, label):
        g = torch.Generator().manual_seed(self.context.seed)
        wo = torch.rand(self.config.n_dirs, 3, generator=g, dtype=torch.float64) * 2 - 1
        wo[:, 2] = wo[:, 2].abs() + 0.1
        wo = wo / wo.norm(dim=1, keepdim=True)
        wi = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64).expand_as(wo)
        value = float(model.eval(wi, wo).mean())
        return [Measurement("acme_mean_f", value, "1/sr", False)]


SPEC = HarnessSpec(name="acme_albedo", description="ACME's toy harness", target="acme_harness:AlbedoHarness")
'''


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    root = tmp_path_factory.mktemp("site")
    (root / "acme_harness.py").write_text(textwrap.dedent(HARNESS))
    conf = root / "acme_harness_conf"
    (conf / "harness").mkdir(parents=True)
    (conf / "__init__.py").write_text("")
    (conf / "harness" / "acme_albedo.yaml").write_text("kind: acme_albedo\nmetrics: []\nn_dirs: 32\n")
    info = root / "acme_harness-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: acme-harness\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[brdfbench.harnesses]\nacme_albedo = acme_harness:SPEC\n\n"
                                           "[brdfbench.conf]\nacme = acme_harness_conf\n")
    return root


def _cli(args, site, cwd):
    env = dict(os.environ, PYTHONPATH=f"{site}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    return subprocess.run([sys.executable, "-m", "brdfbench.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)


def test_a_registered_harness_runs_through_the_cli(site, tmp_path):
    res = tmp_path / "res"
    out = _cli(["harness=acme_albedo", "representation=lambert", "dataset.params.size=small", "limit=2",
                "progress=lines", f"results_dir={res}"], site, tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    df = ResultsStore(res / "brdfbench.sqlite").frame()
    rows = df[df.metric == "acme_mean_f"]
    assert len(rows) == 2 and (rows.value > 0).all() and set(df.harness) == {"acme_albedo"}
    assert "acme_mean_f" in (res / "leaderboard.md").read_text()

    bad = _cli(["harness=acme_albedo", "harness.n_dirs=0", "representation=lambert", "dataset.params.size=small",
                f"results_dir={tmp_path / 'bad'}"], site, tmp_path)
    assert bad.returncode == 2 and "harness.n_dirs=0 must be ≥ 1" in bad.stderr
