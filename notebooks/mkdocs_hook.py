"""mkdocs hook: the notebooks under ``notebooks/`` become pages of the site (``notebooks/NAME/``) without a copy in
``docs/``. mkdocs only collects files under ``docs_dir``; this hook adds the stored notebooks to the site's files
before mkdocs-jupyter turns ``.ipynb`` files into pages (its ``on_files`` runs after this one, by priority), so the
``Notebooks`` section of ``nav`` in ``mkdocs.yml`` can name them as ``notebooks/NAME.ipynb``. mkdocs-jupyter shows
the outputs stored in the notebooks (``execute: false``); ``python notebooks/execute.py`` stores them.
"""

from __future__ import annotations

import pathlib

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

HERE = pathlib.Path(__file__).resolve().parent


@event_priority(100)
def on_files(files, config):
    """Add every ``notebooks/*.ipynb`` to the site's files (source: the repository, page: ``notebooks/NAME/``)."""
    for path in sorted(HERE.glob("*.ipynb")):
        files.append(File(f"{HERE.name}/{path.name}", str(HERE.parent), config["site_dir"],
                          config["use_directory_urls"]))
    return files
