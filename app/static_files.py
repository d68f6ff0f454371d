"""Where the dashboard's files (the top-level static/ folder) are, installed or not.

static/ ships as the package ``deltadash_static`` (see pyproject.toml): a wheel installs it
into site-packages, an editable install maps the name to the checkout's static/. Either way
``importlib.resources`` finds it, so an installed server does not depend on a checkout.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

STATIC_PACKAGE = "deltadash_static"
# A checkout run without installing (PYTHONPATH=., or an editable install made before the
# package existed) has static/ beside app/.
_CHECKOUT_STATIC = Path(__file__).resolve().parent.parent / "static"


def static_dir() -> Path:
    """The folder holding the dashboard's index.html, style.css and js/."""
    try:
        return Path(str(files(STATIC_PACKAGE)))
    except ModuleNotFoundError:
        return _CHECKOUT_STATIC
