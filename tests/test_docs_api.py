"""docs/api.md documents every public name: the package's `__all__` and what each
subpackage's `__init__` re-exports (issue 23)."""

import importlib
import pathlib
import re
import types

import hrgjax

API = (pathlib.Path(__file__).parent.parent / "docs" / "api.md").read_text(encoding="utf-8")
DOCUMENTED = set(re.findall(r"^::: (hrgjax[\w.]*)", API, re.M))
PACKAGES = ("calibration", "diagnosis", "discovery", "fog", "imu", "ins", "nn")


def _documented(obj, *paths):
    """True when one of `paths` or the object's defining module path has an entry."""
    where = getattr(obj, "__module__", None)
    name = getattr(obj, "__name__", None)
    candidates = set(paths) | ({f"{where}.{name}"} if where and name else set())
    return bool(candidates & DOCUMENTED)


def test_every_public_name_has_an_api_entry():
    missing = []
    for name in hrgjax.__all__:
        obj = getattr(hrgjax, name)
        if isinstance(obj, types.ModuleType):  # a subpackage: at least one entry under it
            if not any(
                d == f"hrgjax.{name}" or d.startswith(f"hrgjax.{name}.") for d in DOCUMENTED
            ):
                missing.append(f"hrgjax.{name}")
        elif not _documented(obj, f"hrgjax.{name}"):
            missing.append(f"hrgjax.{name}")
    for pkg in PACKAGES:
        module = importlib.import_module(f"hrgjax.{pkg}")
        for name, obj in vars(module).items():
            if name.startswith("_") or isinstance(obj, types.ModuleType):
                continue
            if not _documented(obj, f"hrgjax.{pkg}.{name}") and not any(
                d.endswith(f".{name}") for d in DOCUMENTED
            ):
                missing.append(f"hrgjax.{pkg}.{name}")
    assert not missing, f"docs/api.md lacks: {missing}"
