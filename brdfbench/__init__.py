"""brdfbench: benchmark and evaluation framework for BRDF representations and generators.

The notebook API (`brdfbench.api`: `datasets`, `representation`, `evaluate`, `render`,
`results`, `generator`, `training_data`) is imported on first use (PEP 562), so `import
brdfbench` stays light.
"""

import types as _types

from . import render as _render_package  # the rendering subpackage; its __init__ imports nothing

__version__ = "0.1.0"

__all__ = ["Scores", "datasets", "evaluate", "generator", "render", "representation", "results", "training_data"]


class _CallableRenderPackage(_types.ModuleType):
    """`brdfbench.render` is the rendering subpackage, and calling it is `brdfbench.api.render`:
    the name is both, and an attribute set by the subpackage's import would shadow a function."""

    def __call__(self, *args, **kwargs):
        from .api import render  # lazy: attribute

        return render(*args, **kwargs)


_render_package.__class__ = _CallableRenderPackage


def __getattr__(name: str):
    if name in __all__:
        from . import api  # lazy: attribute

        return getattr(api, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
