"""Sphinx configuration of the fidelity documentation.

Build (warnings are errors, as in CI)::

    python -m sphinx -W --keep-going -b html docs docs/_build/html
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
# Matplotlib must not look for a display while autodoc imports the package.
os.environ.setdefault("MPLBACKEND", "Agg")

import fidelity  # noqa: E402

project = "fidelity"
author = "the fidelity developers"
copyright = "the fidelity developers"  # noqa: A001
release = fidelity.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]

# Markdown pages: GitHub-style tables and ``$`` math stay plain text; heading anchors so the
# pages can link to each other's sections (``[text](check.md#cameras)``), as on GitHub.
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3

# Docstrings are numpydoc (Parameters / Returns / Raises / Notes / References sections).
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True

autodoc_default_options = {
    "members": True,
    "show-inheritance": True,
    "member-order": "bysource",
}
autodoc_typehints = "description"
# Keep array type hints short (the modules use ``from __future__ import annotations``).
autodoc_type_aliases = {
    "ArrayLike": "numpy.typing.ArrayLike",
    "NDArray": "numpy.typing.NDArray",
    "FloatArray": "numpy.typing.NDArray",
}
autodoc_typehints_format = "short"
autodoc_preserve_defaults = True
autoclass_content = "class"

# Type hints name numpy / click / third-party types that Sphinx cannot (and need not) link.
nitpicky = False

html_theme = "furo"
html_title = f"fidelity {release}"
html_show_sourcelink = False
