"""Sphinx configuration of the fidelity documentation.

Build (warnings are errors, as in CI)::

    python -m sphinx -W --keep-going -b html docs docs/_build/html
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
# Matplotlib must not look for a display while autodoc imports the package.
os.environ.setdefault("MPLBACKEND", "Agg")

import sphinx.util.inspect  # noqa: E402

import fidelity  # noqa: E402

project = "fidelity"
author = "the fidelity developers"
copyright = "the fidelity developers"
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


# A type alias nested in a generic (``tuple[FloatArray, FloatArray]``) is printed with the repr of
# Sphinx's placeholder, ``TypeAliasForwardRef('numpy.typing.NDArray')``: print the alias name.
def _alias_name(self: Any) -> str:
    return str(self.name)


sphinx.util.inspect.TypeAliasForwardRef.__repr__ = _alias_name  # type: ignore[method-assign]

# A long value (a registry such as ``TRANSFORMS``) is dropped from its signature after reading;
# its docstring says what it holds. Short values (``DEFAULT_TABLE = 'coco1000-measured'``) stay.
MAX_VALUE_CHARS = 120


def _drop_long_values(app: Any, doctree: Any) -> None:
    from sphinx import addnodes

    for annotation in list(doctree.findall(addnodes.desc_annotation)):
        value = annotation.astext()
        if value.lstrip().startswith("=") and len(value) > MAX_VALUE_CHARS:
            annotation.parent.remove(annotation)


def setup(app: Any) -> dict[str, Any]:
    app.connect("doctree-read", _drop_long_values)
    return {"parallel_read_safe": True}
