"""Packaging: the bundled example ships as package data, so ``reproduce`` works from an installed
package (not only from a checkout)."""

from __future__ import annotations

import fnmatch
import tomllib

import pytest

from tests.helpers import ROOT


def _package_data_patterns() -> list[str]:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    return cfg["tool"]["setuptools"]["package-data"]["drip_cert"]


def test_every_bundled_data_file_is_declared_package_data():
    """Each file under drip_cert/data matches a package-data pattern (else a wheel omits it)."""
    patterns = _package_data_patterns()
    files = [
        p.relative_to(ROOT / "drip_cert").as_posix()
        for p in (ROOT / "drip_cert" / "data").rglob("*")
        if p.is_file()
    ]
    assert files, "drip_cert/data is empty"
    missing = [f for f in files if not any(fnmatch.fnmatch(f, pat) for pat in patterns)]
    assert missing == []
    assert "py.typed" in patterns and (ROOT / "drip_cert" / "py.typed").is_file()


def test_bundled_spec_is_found_through_the_package_not_the_checkout():
    """``bundled_spec`` resolves through importlib.resources inside the drip_cert package."""
    from drip_cert.workflows import bundled_spec

    path = bundled_spec("paper-4d")
    assert path.is_file()
    assert path.resolve().is_relative_to((ROOT / "drip_cert").resolve())


def test_unknown_experiment_is_a_spec_error():
    from drip_cert.errors import SpecError
    from drip_cert.workflows import bundled_spec

    with pytest.raises(SpecError, match="available: paper-4d"):
        bundled_spec("paper-5d")


def test_every_public_name_resolves():
    """Each name of drip_cert.__all__ maps to a module that defines it (the lazy re-exports)."""
    import drip_cert

    for name in drip_cert.__all__:
        assert getattr(drip_cert, name) is not None, name
    with pytest.raises(AttributeError):
        drip_cert.no_such_name  # noqa: B018
