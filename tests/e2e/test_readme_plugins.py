"""The README's "Registering your own plugins": every block marked `<!-- readme-test: NAME -->`
runs as written. Each plugin's module files go into a package under tmp_path, its spec is
found through the entry point its ```toml block names and registered in-process, and then
it runs for real: the kit line of the README where a kit exists, and the plugin through
the API or the pipeline where one does not (or as well)."""

from __future__ import annotations

import math
import re
import sys
import tomllib
from pathlib import Path

import pytest
import torch

import brdfbench as bb
from brdfbench.plugins import registry
from brdfbench.errors import ConfigError
from brdfbench.plugins.specs import import_target

REPO = Path(__file__).resolve().parents[2]
SECTION = "## Registering your own plugins"
PACKAGE = "my_package"
#: plugin block -> (registry group, name) its ```toml block must register
PLUGINS = {
    "representation": ("representations", "my_lambert"),
    "generator": ("generators", "my_albedo_gaussian"),
    "metric": ("metrics", "my_rel_l1"),
    "harness": ("harnesses", "my_albedo"),
    "dataset": ("datasets", "my_diffuse"),
    "sampler": ("samplers", "my_uniform"),
}
KITS = ("representation", "generator", "metric", "harness", "dataset", "sampler")
EXPECTED = {**{p: "python" for p in PLUGINS}, **{f"{p}.toml": "toml" for p in PLUGINS},
            **{f"{p}.kit": "python" for p in KITS}}
MARK = re.compile(r"^<!-- readme-test: (?P<name>[\w.-]+) -->\n", re.M)
BLOCK = re.compile(r"```(?P<lang>\w+)\n(?P<code>.*?)^```$", re.M | re.S)
FILE = re.compile(rf"^# ({PACKAGE}/\w+\.py)$", re.M)
#: the README's dataset (ρ of its two materials)
GREY, RED = (0.5, 0.5, 0.5), (0.6, 0.1, 0.1)


def _section() -> str:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert text.count(f"\n{SECTION}\n") == 1, f"README.md has no single '{SECTION}' section"
    body = text.split(f"\n{SECTION}\n", 1)[1]
    return body.split("\n## ", 1)[0]


def readme_blocks() -> dict[str, tuple[str, str]]:
    """name -> (fence language, code) of every marked block in the section."""
    body, found = _section(), {}
    for mark in MARK.finditer(body):
        name = mark["name"]
        fence = BLOCK.match(body, mark.end())
        assert fence, f"README.md: the marker readme-test: {name} is not right above a fenced block"
        assert name not in found, f"README.md: readme-test: {name} marks two blocks"
        found[name] = (fence["lang"], fence["code"])
    return found


BLOCKS = readme_blocks()


def block(name: str) -> str:
    assert name in BLOCKS, f"README.md's '{SECTION}' has no block marked <!-- readme-test: {name} -->"
    lang, code = BLOCKS[name]
    assert lang == EXPECTED[name], f"readme-test: {name} is a ```{lang} block, expected ```{EXPECTED[name]}"
    return code


def module_files(name: str) -> dict[str, str]:
    """The files of a plugin block: each starts at a line `# my_package/NAME.py`."""
    code = block(name)
    heads = list(FILE.finditer(code))
    assert heads and not code[:heads[0].start()].strip(), f"readme-test: {name} must start with '# {PACKAGE}/….py'"
    return {h[1]: code[h.end():(heads[i + 1].start() if i + 1 < len(heads) else len(code))]
            for i, h in enumerate(heads)}


def entry_point(name: str) -> tuple[str, str, str]:
    """(group, plugin name, target) of the block's ```toml entry point (exactly one)."""
    table = tomllib.loads(block(f"{name}.toml"))["project"]["entry-points"]
    [(group, points)] = table.items()
    [(plugin, target)] = points.items()
    assert group.startswith("brdfbench.") and group[len("brdfbench."):] in registry.GROUPS, f"unknown group {group}"
    return group[len("brdfbench."):], plugin, target


def _forget_package() -> None:
    for mod in [m for m in sys.modules if m == PACKAGE or m.startswith(PACKAGE + ".")]:
        del sys.modules[mod]


@pytest.fixture
def install(tmp_path, monkeypatch):
    """`install(*plugins)`: write those README blocks into one package (files of the same
    name appended, as `specs.py` is), put it on sys.path, and register each spec that its
    entry point names; unregistered afterwards."""
    registered: list[tuple[str, str]] = []

    def add(*plugins: str) -> None:
        root = tmp_path / "site"
        (root / PACKAGE).mkdir(parents=True, exist_ok=True)
        (root / PACKAGE / "__init__.py").touch()
        for p in plugins:
            for path, code in module_files(p).items():
                with open(root / path, "a", encoding="utf-8") as f:
                    f.write(code)
        monkeypatch.syspath_prepend(str(root))
        for p in plugins:
            group, name, target = entry_point(p)
            assert (group, name) == PLUGINS[p], f"readme-test: {p}.toml registers {group}:{name}"
            spec = import_target(target)
            assert isinstance(spec, registry.GROUPS[group]) and spec.name == name, (
                f"{target} is {spec!r}, expected a {registry.GROUPS[group].__name__} named {name!r}")
            registry.register(group, spec)
            registered.append((group, name))

    _forget_package()
    try:
        yield add
    finally:
        for group, name in registered:
            registry.unregister(group, name)
        _forget_package()


def run_kit(name: str) -> None:
    exec(compile(block(f"{name}.kit"), f"README.md (readme-test: {name}.kit)", "exec"), {})


def lambert_fit(material):
    return bb.representation("lambert").fit(material)


# --------------------------------------------------------------------------- the blocks


def test_every_plugin_has_its_marked_blocks():
    assert set(BLOCKS) == set(EXPECTED), (f"marked blocks missing: {sorted(set(EXPECTED) - set(BLOCKS))}, "
                                          f"unexpected: {sorted(set(BLOCKS) - set(EXPECTED))}")
    for name in PLUGINS:
        files = module_files(name)
        assert f"{PACKAGE}/specs.py" in files and len(files) == 2, f"{name}: specs.py and one module, not {list(files)}"
        target = entry_point(name)[2]
        assert target.startswith(f"{PACKAGE}.specs:"), f"{name}: the entry point must name the light specs module"
        lines = sum(len(code.strip().splitlines()) for code in files.values())
        assert lines <= 40, f"readme-test: {name} has {lines} lines of code: keep the examples short"


# --------------------------------------------------------------------------- each plugin


def test_representation_passes_the_kit_and_fits_what_it_says(install):
    install("representation", "dataset")
    run_kit("representation")
    fitted = bb.representation("my_lambert").fit(bb.datasets("my_diffuse", scale=0.5).load("red-diffuse"))
    wi = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    wo = torch.tensor([[0.6, 0.0, 0.8], [0.6, 0.0, -0.8]], dtype=torch.float64)
    out = fitted.eval(wi, wo)
    assert torch.allclose(out[0], 0.5 * torch.tensor(RED, dtype=torch.float64) / math.pi)  # ρ/π above the horizon
    assert bool((out[1] == 0).all())  # 0 below it


def test_generator_passes_the_kit_and_samples_the_albedos_it_learned(install):
    install("generator", "dataset")
    run_kit("generator")
    gen = bb.generator("my_albedo_gaussian").fit(bb.training_data(bb.datasets("my_diffuse")))
    samples = gen.sample(4000, seed=0)
    mean = torch.tensor([(g + r) / 2 for g, r in zip(GREY, RED)], dtype=torch.float64)
    assert torch.allclose(gen.mean, mean, atol=1e-6) and torch.allclose(samples.array.mean(0), mean, atol=0.02)
    assert samples.representation == "lambert"
    wi = wo = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
    assert torch.allclose(samples[7].eval(wi, wo)[0], samples.array[7] / math.pi)


def test_metric_passes_the_kit_and_scores_in_the_accuracy_harness(install):
    install("metric", "dataset")
    run_kit("metric")
    data = bb.datasets("my_diffuse")
    grey, red = data.load("grey-diffuse"), data.load("red-diffuse")
    scores = bb.evaluate(lambert_fit(grey), red, metrics=["my_rel_l1", "l1"], n_random=1024, cost=False)
    expected = sum(abs(g - r) / math.pi / (r / math.pi + 0.01) for g, r in zip(GREY, RED)) / 3
    assert scores["my_rel_l1"] == pytest.approx(expected, rel=1e-5)
    assert scores.measurements[0].unit == "1" and not scores.measurements[0].higher_is_better
    assert bb.evaluate(lambert_fit(red), red, metrics=["my_rel_l1"], cost=False)["my_rel_l1"] < 1e-6


def test_dataset_passes_the_kit_loads_and_its_materials_fit(install):
    install("dataset")
    run_kit("dataset")
    data = bb.datasets("my_diffuse", scale=0.5)
    assert data.materials == ("grey-diffuse", "red-diffuse") and len(data) == 2
    assert data.fingerprint != bb.datasets("my_diffuse").fingerprint  # other data, another fingerprint
    materials = list(data)
    assert [m.category for m in materials] == ["diffuse", "diffuse"] and data.category("red-diffuse") == "diffuse"
    for m, rho in zip(materials, (GREY, RED)):
        assert m.table.valid.all()
        albedo = lambert_fit(m).state_dict()["albedo"]
        assert torch.allclose(albedo, 0.5 * torch.tensor(rho, dtype=torch.float64), rtol=1e-6)
    with pytest.raises(ConfigError, match="dataset.params.size"):
        bb.datasets("my_diffuse", size="small")  # the README's claim: the default dataset's keys are refused


def test_harness_passes_the_kit_and_measures_through_the_pipeline(install, tmp_path):
    from brdfbench.harness import HarnessContext
    from brdfbench.pipeline.config import RunConfig, harness_config
    from brdfbench.pipeline.sweep import run_job as run
    from brdfbench.store.sqlite import ResultsStore

    install("harness", "dataset")
    run_kit("harness")
    with pytest.raises(ConfigError, match="harness.n_dirs=0 must be ≥ 1"):
        harness_config("my_albedo", n_dirs=0)
    with pytest.raises(ConfigError, match="unknown config key harness.n_random"):
        harness_config("my_albedo", n_random=4096)
    config = harness_config("my_albedo", n_dirs=2048)

    counts = run(RunConfig(representation="lambert", representation_params={}, label="lambert", dataset="my_diffuse",
                           dataset_params={}, harness=config, results_dir=tmp_path / "results", isolate=False,
                           progress="none"))
    assert counts == {"done": 2, "skipped": 0, "failed": 0}
    df = ResultsStore(tmp_path / "results" / "brdfbench.sqlite").frame()
    rows = df[df.metric == "albedo_error"]
    assert sorted(rows.material) == ["grey-diffuse", "red-diffuse"] and set(df.harness) == {"my_albedo"}
    assert (rows.value.abs() < 1e-6).all() and set(rows.unit) == {"1"}

    # a wrong model: grey's albedo against red's table, |0.5 − ρ| averaged over RGB
    data = bb.datasets("my_diffuse")
    context = HarnessContext(scene=None, metric_specs=[], seed=0, results_dir=tmp_path, dataset_fingerprint="",
                             representation="lambert", representation_params={}, scene_name="brdf_space",
                             scene_params={})
    harness = registry.get("harnesses", "my_albedo").load()(config, context)
    [m] = harness.measure(lambert_fit(data.load("grey-diffuse")), data.load("red-diffuse"), "lambert")
    assert m.metric == "albedo_error" and m.value == pytest.approx(sum(abs(0.5 - r) for r in RED) / 3, rel=1e-9)


def test_sampler_passes_the_kit(install):
    install("sampler")
    run_kit("sampler")
    sampler = registry.get("samplers", "my_uniform").create()
    wi = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64).expand(100_000, 3)
    wo = sampler.sample(wi, torch.rand(100_000, 2, generator=torch.Generator().manual_seed(0), dtype=torch.float64))
    assert float(wo[:, 2].mean()) == pytest.approx(0.5, abs=0.01)  # E[cos θ] = 1/2 uniform over the hemisphere
    assert torch.allclose(sampler.pdf(wi, wo), torch.full((100_000,), 1 / (2 * math.pi), dtype=torch.float64))
