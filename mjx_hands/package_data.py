"""Where the project's data folders are: ``scenes/`` and ``mocap_data/`` sit at the top of
a checkout (the product's layout) and inside the package once installed from a wheel
(``pyproject.toml`` maps them to ``mjx_hands/scenes`` and ``mjx_hands/mocap_data``)."""

from __future__ import annotations

from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_ROOT = PACKAGE_DIR.parent
"""The checkout (or, when installed, the folder holding the package)."""


def data_dir(name: str) -> Path:
    """The folder ``name`` ('scenes', 'mocap_data'): the checkout's, else the installed copy."""
    for candidate in (REPO_ROOT / name, PACKAGE_DIR / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(
        f"the project's {name}/ folder is missing: looked in {REPO_ROOT / name} (a checkout) "
        f"and {PACKAGE_DIR / name} (an installed package); reinstall mjx_hands"
    )
