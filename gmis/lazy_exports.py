"""Names a module re-exports from other modules, imported on first use (PEP 562), so that
importing the module stays light (docs/DESIGN.md "Start-up time")."""

import sys
from importlib import import_module


def lazy_getattr(module_name: str, exports: dict):
    """A module ``__getattr__`` for ``module_name``: a name in ``exports`` (name → module
    path) is imported from its module on first access and kept in the module's namespace;
    any other name raises AttributeError as a plain module would."""
    namespace = vars(sys.modules[module_name])

    def __getattr__(name):
        if name in exports:
            value = getattr(import_module(exports[name]), name)
            namespace[name] = value
            return value
        raise AttributeError(f"module {module_name!r} has no attribute {name!r}")

    return __getattr__


__all__ = ["lazy_getattr"]
