import pytest

from brdfbench.plugins import registry
from brdfbench.errors import PluginError
from brdfbench.plugins.specs import MetricSpec, RepresentationSpec


def test_builtins_are_registered_through_entry_points():
    assert {"merl", "lambert"} <= set(registry.names("representations"))
    assert {"synthetic", "merl_folder", "nbrdf_release"} <= set(registry.names("datasets"))
    assert {"l1", "l1_log", "l1_log_cos", "hdr_rmse", "hdr_mae"} <= set(registry.names("metrics"))
    assert "brdf_space" in registry.names("scenes")
    assert registry.names("generators") == sorted(registry.names("generators"))


def test_every_spec_loads_with_matching_type_and_name():
    for group, spec_type in registry.GROUPS.items():
        for spec in registry.all_specs(group):
            assert isinstance(spec, spec_type)
            assert spec.description and "\n" not in spec.description
            assert spec.load() is not None


def test_unknown_name_suggests_close_match():
    with pytest.raises(PluginError, match=r"unknown representation 'lambret'.*Did you mean 'lambert'"):
        registry.get("representations", "lambret")


def test_unknown_name_without_close_match_lists_registered():
    with pytest.raises(PluginError, match=r"Registered: .*lambert"):
        registry.get("representations", "zzzzzz")


def test_unknown_group():
    with pytest.raises(PluginError, match="unknown plugin group 'models'"):
        registry.names("models")


def test_in_process_registration_and_type_check():
    spec = RepresentationSpec(name="tmp_rep", description="x", target="brdfbench_representations.lambert:Lambert")
    registry.register("representations", spec)
    try:
        assert registry.get("representations", "tmp_rep") is spec
        assert "tmp_rep" in registry.names("representations")
    finally:
        registry.unregister("representations", "tmp_rep")
    with pytest.raises(PluginError, match="must be a MetricSpec"):
        registry.register("metrics", spec)
    assert "tmp_rep" not in registry.names("representations")


def test_bad_target_is_a_plugin_error():
    spec = RepresentationSpec(name="broken", description="x", target="no_such_module_xyz:Thing")
    with pytest.raises(PluginError, match="cannot import plugin module 'no_such_module_xyz'"):
        spec.load()
    spec = RepresentationSpec(name="broken", description="x", target="brdfbench.coords:NoSuchThing")
    with pytest.raises(PluginError, match="has no attribute 'NoSuchThing'"):
        spec.load()
    with pytest.raises(PluginError, match="must look like"):
        MetricSpec(name="m", description="x", target="nocolon").load()


def test_listing_imports_no_implementation():
    import subprocess
    import sys

    code = (
        "import sys; from brdfbench.plugins import registry\n"
        "[registry.get(g, n) for g in registry.GROUPS for n in registry.names(g)]\n"
        "heavy = [m for m in ('brdfbench_representations.merl', 'brdfbench_representations.lambert', 'torch') if m in sys.modules]\n"
        "print(heavy)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
