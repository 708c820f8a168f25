"""Package namespaces whose names are imported when first asked for, so that importing the
package (and a light module in it, such as a command line's options) stays cheap.
"""

from __future__ import annotations

import importlib


def exports(package: str, public: dict[str, str]):
    """``(__getattr__, __dir__)`` for ``package``'s namespace: each name of ``public`` (name ->
    the module it comes from; a module's own name stands for the module itself) is imported on
    first use and kept in the package's globals.
    """
    namespace = importlib.import_module(package).__dict__

    def __getattr__(name: str):
        if name not in public:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module = importlib.import_module(public[name])
        value = module if module.__name__.endswith("." + name) else getattr(module, name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(public))

    return __getattr__, __dir__
