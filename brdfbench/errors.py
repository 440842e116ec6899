"""Exception types. Each message names the file, key or value at fault."""


class BrdfbenchError(Exception):
    """Base class: the CLI turns these into a one-line message and exit status 2."""


class DataError(BrdfbenchError):
    """A data file (MERL .binary, NBRDF .h5, folder) is unreadable or malformed."""


class ModelFileError(BrdfbenchError):
    """A saved model file is malformed or is a pickle (which is never loaded)."""


class PluginError(BrdfbenchError):
    """A plugin name is unknown, or its entry point is broken."""


class ConfigError(BrdfbenchError):
    """A configuration value is invalid."""


class RenderError(BrdfbenchError):
    """A render produced non-finite values, or a scene/environment map is unusable."""


def os_error(exc: OSError, what: str = "") -> str:
    """One line for an OSError: the file it names, what was being done, and the system's words."""
    where = exc.filename if exc.filename is not None else ""
    words = exc.strerror or str(exc)
    head = f"{where}: " if where else ""
    return f"{head}{words}" + (f" ({what})" if what else "")
