"""Sphinx configuration of the sb3-pilot docs (Stable-Baselines3's stack: autodoc, Read-the-Docs theme)."""

import os
import sys

sys.path.insert(0, os.path.abspath(".."))
os.environ.setdefault("MUJOCO_GL", "osmesa")
os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

from sb3_pilot.version import __version__

project = "sb3-pilot"
author = "sb3-pilot contributors"
copyright = "2026, sb3-pilot contributors"
version = release = __version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "sphinx.ext.mathjax",
    "sphinx-mathjax-offline",  # serves MathJax from _static/mathjax: the equations render without internet
    "sphinx.ext.intersphinx",
    "myst_parser",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
# $...$, $$...$$ and \begin{align}...\end{align} in the Markdown pages are parsed as math (MathJax renders them)
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3
exclude_patterns = ["_build"]
templates_path: list[str] = []

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autoclass_content = "class"
autodoc_default_options = {"members": True, "show-inheritance": True}
# SB3's base classes are documented on SB3's site; no network access is needed to build these docs.
intersphinx_mapping: dict[str, tuple[str, None]] = {}

html_theme = "sphinx_rtd_theme"
html_title = f"sb3-pilot {release}"
# long code lines and table cells wrap instead of scrolling sideways
html_static_path = ["_static"]
html_css_files = ["wrap.css"]
