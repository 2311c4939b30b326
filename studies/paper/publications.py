"""The one place where the harness's models meet the publications' names for them.

A model's name in a publication is declared with its part in the studies (``published``,
:mod:`studies.sweep.roles`); the publication's data file of models
(``studies/data/<key>_models.csv``) gives the part each name plays in the publication's claims
(``role``: ``proposed``, ``no-face-diagonals``, ...).  Study code asks for a model by that role and
joins with the published tables by the publication's own name; the studies store the join as
``tables/published_models.csv`` for the report.  So no code outside a model's module compares a
model's name.
"""

from __future__ import annotations

import pandas as pd

from hybmss import models

from studies.sweep import roles
from studies.paper.values import load

PUBLICATIONS = ("G20", "B09")
"""Keys of the publications with data in ``studies/data`` (lower case in the file names)."""


def models_of(publication: str) -> pd.DataFrame:
    """The models ``publication`` compares, one row each: ``publication``, ``name`` (the
    publication's name, as in its tables), ``role`` (its part in the publication's claims),
    ``description`` and ``model``, the registered model that declares that name in its
    ``published`` (``""`` if none does)."""
    t = load(f"{publication.lower()}_models")
    own = {roles.published(m)[publication]: m for m in models.names() if publication in roles.published(m)}
    t["model"] = t["name"].map(own).fillna("")
    t.insert(0, "publication", publication)
    return t


def published_models() -> pd.DataFrame:
    """:func:`models_of` every publication of :data:`PUBLICATIONS`, in one table."""
    return pd.concat([models_of(p) for p in PUBLICATIONS], ignore_index=True)


def model_in(publication: str, role: str) -> str | None:
    """The registered model that plays ``role`` in ``publication`` (None if none is registered)."""
    t = models_of(publication)
    hit = t[(t["role"] == role) & (t["model"] != "")]
    return None if hit.empty else str(hit["model"].iloc[0])


def published_name(model: str, publication: str) -> str | None:
    """The name ``publication``'s tables give the registered ``model`` (None if it reports none)."""
    return roles.published(models.get(model).name).get(publication)


def model_named(publication: str, name: str) -> str | None:
    """The registered model that ``publication`` calls ``name`` (None if none declares it)."""
    return next((m for m in models.names() if roles.published(m).get(publication) == name), None)


