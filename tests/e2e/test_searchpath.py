"""Config groups shipped by installed third-party packages (the `brdfbench.conf` entry-point
group, read by `hydra_plugins/brdfbench_searchpath`), and the launcher presets of the
packaged conf.

One test installs a real package with `pip install -e --no-deps --no-build-isolation` into
the running interpreter's environment (and uninstalls it afterwards); it registers only a
config package, no plugin, so that a `brdfbench list` run elsewhere meanwhile is unchanged.
The others put a package and its .dist-info on PYTHONPATH of a subprocess, as
test_third_party.py does.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import textwrap
import uuid
from importlib import resources
from importlib.metadata import EntryPoint, distributions
from pathlib import Path

import pytest

from hydra.core.plugins import Plugins
from hydra.plugins.search_path_plugin import SearchPathPlugin
from hydra._internal.config_search_path_impl import ConfigSearchPathImpl

import hydra_plugins.brdfbench_searchpath as searchpath
from brdfbench.hydra import packages as conf_packages

SMOKE = ["dataset.params.size=small", "harness=quick", "limit=1"]


def _brdfbench(args, cwd, pythonpath=None, timeout=600):
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = os.pathsep.join([str(pythonpath), env.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-m", "brdfbench.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


COMPOSE = """
import json, sys
from hydra import compose, initialize_config_module
from omegaconf import OmegaConf
out = []
with initialize_config_module(version_base="1.3", config_module="brdfbench_conf"):
    for overrides, key in json.loads(sys.argv[1]):
        try:
            cfg = compose("config", overrides=overrides, return_hydra_config=key is not None)
            out.append({"config": OmegaConf.to_yaml(OmegaConf.select(cfg, key) if key else cfg)})
        except Exception as exc:
            out.append({"error": f"{type(exc).__name__}: {exc}"})
print(json.dumps(out))
"""


def _compose(override_sets, cwd, pythonpath=None, key=None):
    """Compose brdfbench's config for each list of overrides in one fresh interpreter (whose
    environment sees the packages installed or put on PYTHONPATH by the test); runs no
    benchmark. Returns, for each, the job config (or the node at `key`, e.g. "hydra.launcher")
    as YAML text, or the error message."""
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = os.pathsep.join([str(pythonpath), env.get("PYTHONPATH", "")])
    request = json.dumps([[overrides, key] for overrides in override_sets])
    result = subprocess.run([sys.executable, "-c", COMPOSE, request], cwd=cwd, env=env,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    return [item.get("config") or item["error"] for item in json.loads(result.stdout.splitlines()[-1])]


# ---------------------------------------------------------------------------------------
# The plugin itself (in process)


def test_hydra_discovers_the_plugin():
    """`hydra_plugins` is a namespace package; the editable install puts ./hydra_plugins
    on its path (pyproject lists `hydra_plugins` among the packages for that)."""
    found = Plugins.instance().discover(SearchPathPlugin)
    assert searchpath.BrdfbenchSearchPathPlugin in found, found
    assert not (Path(searchpath.__file__).parents[1] / "__init__.py").exists()


def _search_path(primary):
    path = ConfigSearchPathImpl()
    path.append("hydra", "pkg://hydra.conf")
    path.append("main", primary)
    return path


def _entry_points(monkeypatch, *pairs):
    eps = [EntryPoint(name, value, searchpath.ENTRY_POINT_GROUP) for name, value in pairs]
    # the entry points are listed by brdfbench.hydra.packages, which the plugin and the core share
    monkeypatch.setattr(conf_packages, "entry_points", lambda group: [e for e in eps if e.group == group])


def test_appends_packages_after_the_primary_and_skips_what_does_not_import(monkeypatch, capsys):
    _entry_points(monkeypatch, ("zeta", "json"), ("own", "brdfbench_conf"), ("alpha", "email:ignored"),
                  ("gone", "no_such_package_for_brdfbench"), ("zz_dup", "json"), ("module", "textwrap"))
    path = _search_path("pkg://brdfbench_conf")
    searchpath.BrdfbenchSearchPathPlugin().manipulate_search_path(path)
    elements = [(e.provider, e.path) for e in path.get_path()]
    assert elements == [
        ("hydra", "pkg://hydra.conf"),
        ("main", "pkg://brdfbench_conf"),  # brdfbench's own conf: not added twice
        (f"{searchpath.PROVIDER}:alpha", "pkg://email"),  # by entry-point name; ":attr" dropped
        (f"{searchpath.PROVIDER}:zeta", "pkg://json"),  # `zz_dup` (sorted after it) names the same package
    ]
    err = capsys.readouterr().err
    assert "no_such_package_for_brdfbench" in err and "brdfbench.conf:gone" in err
    assert "textwrap" in err  # a module, not a package: it cannot hold config folders


def test_leaves_other_hydra_apps_alone(monkeypatch):
    _entry_points(monkeypatch, ("zeta", "json"))
    path = _search_path("pkg://some_other_app.conf")
    searchpath.BrdfbenchSearchPathPlugin().manipulate_search_path(path)
    assert [e.path for e in path.get_path()] == ["pkg://hydra.conf", "pkg://some_other_app.conf"]


# ---------------------------------------------------------------------------------------
# A real editable install


@pytest.fixture(scope="module")
def editable_conf_package(tmp_path_factory):
    """A distribution whose only content is a config package, laid out as brdfbench's own
    (`package-dir = {pkg = "conf"}`, so setuptools' editable finder maps it), installed
    with `pip install -e`; a unique name, so concurrent runs do not uninstall each other's."""
    tag = uuid.uuid4().hex[:8]
    dist, package = f"brdfbench-test-conf-{tag}", f"brdfbench_test_conf_{tag}"
    root = tmp_path_factory.mktemp("editable_conf")
    (root / "pyproject.toml").write_text(textwrap.dedent(f"""\
        [build-system]
        requires = ["setuptools>=68"]
        build-backend = "setuptools.build_meta"

        [project]
        name = "{dist}"
        version = "0.1"

        [project.entry-points."brdfbench.conf"]
        test_conf_{tag} = "{package}"

        [tool.setuptools]
        package-dir = {{ "{package}" = "conf" }}
        packages = ["{package}"]

        [tool.setuptools.package-data]
        {package} = ["*/*.yaml"]
    """))
    conf = root / "conf"
    (conf / "representation").mkdir(parents=True)
    (conf / "__init__.py").write_text("")
    (conf / "representation" / "mylambert.yaml").write_text(
        "# The built-in lambert plugin under a label of its own (third-party test config).\n"
        "name: lambert\nlabel: mylambert\nparams: {}\n")
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    stale = [d.metadata["Name"] for d in distributions() if (d.metadata["Name"] or "").startswith("brdfbench-test-conf-")
             and not any(_installed(ep.value) for ep in d.entry_points)]  # left by a killed run: source gone
    if stale:
        subprocess.run([*pip, "uninstall", "-y", *stale], capture_output=True, text=True, timeout=300)
    installed = subprocess.run([*pip, "install", "-e", str(root), "--no-deps", "--no-build-isolation"],
                               cwd=root, capture_output=True, text=True, timeout=300)
    assert installed.returncode == 0, installed.stdout + installed.stderr
    try:
        yield {"dist": dist, "package": package, "root": root}
    finally:
        subprocess.run([*pip, "uninstall", "-y", dist], capture_output=True, text=True, timeout=300)


def test_editable_install_adds_its_representation(editable_conf_package, tmp_path):
    # A file added to the source tree shows without reinstalling: the install is editable.
    edited = editable_conf_package["root"] / "conf" / "representation" / "mylambert_edited.yaml"
    edited.write_text("name: lambert\nlabel: mylambert_edited\nparams: {}\n")
    mine, later = _compose([["representation=mylambert"], ["representation=mylambert_edited"]], tmp_path)
    assert "label: mylambert" in mine and "name: lambert" in mine
    assert "label: mylambert_edited" in later

    run = _brdfbench(["representation=mylambert", *SMOKE, f"results_dir={tmp_path}/res"], tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "mylambert" in (tmp_path / "res" / "leaderboard.md").read_text()


# ---------------------------------------------------------------------------------------
# A package and its own plugin on PYTHONPATH (no pip)

ACME_SPECS = '''
from brdfbench.plugins.specs import RepresentationSpec

ACME_LAMBERT = RepresentationSpec(
    name="acme_lambert", description="ACME's Lambert (third-party search-path test plugin)",
    target="brdfbench_representations.lambert:Lambert",
    tags=frozenset({"isotropic", "reciprocal", "fittable", "analytic"}),
)
'''


@pytest.fixture(scope="module")
def acme_site(tmp_path_factory):
    """acme_brdf: a representation plugin, and acme_brdf.conf with two config groups and a
    `representation/lambert.yaml` that must not replace the built-in one."""
    root = tmp_path_factory.mktemp("acme_site")
    pkg = root / "acme_brdf"
    conf = pkg / "conf"
    (conf / "representation").mkdir(parents=True)
    (conf / "dataset").mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "specs.py").write_text(textwrap.dedent(ACME_SPECS))
    (conf / "__init__.py").write_text("")
    (conf / "representation" / "acme_lambert.yaml").write_text("name: acme_lambert\nlabel: acme_lambert\nparams: {}\n")
    (conf / "representation" / "lambert.yaml").write_text("name: acme_lambert\nlabel: acme_shadow\nparams: {}\n")
    (conf / "dataset" / "acme_tiny.yaml").write_text("name: synthetic\nparams:\n  size: small\n  seed: 3\n")
    info = root / "acme_brdf-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: acme-brdf\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        "[brdfbench.representations]\nacme_lambert = acme_brdf.specs:ACME_LAMBERT\n\n"
        "[brdfbench.conf]\nacme = acme_brdf.conf\n")
    return root


def test_third_party_groups_compose(acme_site, tmp_path):
    own, builtin, unknown = _compose([["representation=acme_lambert", "dataset=acme_tiny"],
                                      ["representation=lambert"],
                                      ["representation=no_such_option_here"]], tmp_path, acme_site)
    assert "label: acme_lambert" in own and "seed: 3" in own
    # Appended after brdfbench's own conf: a third party adds options, it replaces none.
    assert "name: lambert" in builtin and "acme" not in builtin
    # Hydra's message for an unknown option lists the third-party options with the built-in ones.
    assert "no_such_option_here" in unknown and "acme_lambert" in unknown and "merl_trilinear" in unknown


@pytest.mark.slow  # composing is tested above; the run itself is test_third_party's
def test_third_party_plugin_and_config_run(acme_site, tmp_path):
    run = _brdfbench(["representation=acme_lambert", "dataset=acme_tiny", "harness=quick", "limit=1",
                      f"results_dir={tmp_path}/res"], tmp_path, acme_site)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "`acme_lambert`" in (tmp_path / "res" / "leaderboard.md").read_text()


# ---------------------------------------------------------------------------------------
# Launcher presets (conf/hydra/launcher/brdfbench_*.yaml) extend the plugins' own configs

PRESETS = {
    "brdfbench_joblib": ("hydra_plugins.hydra_joblib_launcher", "JoblibLauncher", "joblib"),
    "brdfbench_submitit_local": ("hydra_plugins.hydra_submitit_launcher", "LocalLauncher", "submitit_local"),
    "brdfbench_submitit_slurm": ("hydra_plugins.hydra_submitit_launcher", "SlurmLauncher", "submitit_slurm"),
    "brdfbench_ray": ("hydra_plugins.hydra_ray_launcher", "RayLauncher", "ray"),
}


def _installed(module):
    try:
        return importlib.util.find_spec(module) is not None
    except ImportError:
        return False


def test_launcher_presets_extend_the_plugin_configs(tmp_path):
    """Each preset composes to its plugin's launcher with brdfbench's settings on top, and the
    plugin's own option (`hydra/launcher=joblib` ...) still resolves to the plugin's config:
    no file of the same name in the package conf shadows it."""
    presets = resources.files("brdfbench_conf") / "hydra" / "launcher"
    wanted = [name for name, (module, _, _) in sorted(PRESETS.items()) if _installed(module)]
    if not wanted:
        pytest.skip("no launcher plugin installed (pip install -e '.[launchers]')")
    composed = _compose([[f"hydra/launcher={option}"] for name in wanted for option in (name, PRESETS[name][2])],
                        tmp_path, key="hydra.launcher")
    for i, name in enumerate(wanted):
        module, launcher_class, plugin_option = PRESETS[name]
        own, plugin = composed[2 * i], composed[2 * i + 1]
        assert f"_target_: {module}." in own and f".{launcher_class}" in own, own
        assert f".{launcher_class}" in plugin, plugin
        assert (presets / f"{name}.yaml").is_file() and not (presets / f"{plugin_option}.yaml").is_file()
        if name == "brdfbench_joblib":
            assert "backend: loky" in own and "backend: null" in plugin
        if name.startswith("brdfbench_submitit"):
            assert "timeout_min: 1440" in own and "timeout_min: 60" in plugin
        if name == "brdfbench_ray":
            assert "include_dashboard: false" in own and "include_dashboard" not in plugin


# The joblib preset's sweep runs in tests/e2e/test_sweeps.py
# (test_two_launchers_write_one_store_without_loss_or_duplicates), beside a basic-launcher run.
@pytest.mark.parametrize("preset", [
    pytest.param("brdfbench_submitit_local", marks=pytest.mark.slow),  # Slurm's code path, locally
])
def test_sweep_on_a_launcher(preset, tmp_path):
    module = PRESETS[preset][0]
    if not _installed(module):
        pytest.skip(f"{module} not installed (pip install -e '.[launchers]')")
    overrides = [f"hydra/launcher={preset}", "representation=lambert,merl", *SMOKE, f"results_dir={tmp_path}/res"]
    if preset == "brdfbench_joblib":
        overrides.append("hydra.launcher.n_jobs=2")
    run = _brdfbench(["-m", *overrides], tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    leaderboard = (tmp_path / "res" / "leaderboard.md").read_text()
    assert "`lambert`" in leaderboard and "`merl`" in leaderboard


@pytest.mark.slow
def test_sweep_on_ray(tmp_path):
    if not _installed("hydra_plugins.hydra_ray_launcher"):
        pytest.skip("hydra-ray-launcher not installed (pip install -e '.[launchers]')")
    run = _brdfbench(["-m", "hydra/launcher=brdfbench_ray", "representation=lambert,merl", *SMOKE,
                      f"results_dir={tmp_path}/res"], tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    leaderboard = (tmp_path / "res" / "leaderboard.md").read_text()
    assert "`lambert`" in leaderboard and "`merl`" in leaderboard
