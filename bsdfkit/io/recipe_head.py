"""The head of a fitting recipe: its name and the measurement folder it reduces.

A recipe's ``[recipe]`` table is read in two places: by the main job, which parses the whole recipe, and by
:func:`bsdfkit.pipeline.plate_from_scan.plate_from_recipe`, the plate resolver of scenes whose phosphor top comes
from a recipe (``[top] from = "fitting/<recipe>.toml"``).
Both read it here, so a recipe's measurement resolves, and a faulty head is refused, the same way in both.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, NamedTuple

from bsdfkit.core.errors import InputError
from bsdfkit.io.text import read_toml


class RecipeHead(NamedTuple):
    """What a recipe's ``[recipe]`` table names."""

    name: str
    measurement: Path


def recipe_head(data: dict[str, Any], path: str | Path) -> RecipeHead:
    """The name and measurement folder of a parsed recipe.

    Parameters
    ----------
    data : dict
        The recipe's parsed TOML document.
    path : str or Path
        The recipe's file, named in errors; the measurement path is resolved relative to its folder.

    Returns
    -------
    RecipeHead
        The recipe's name and its measurement folder (an absolute path).

    Raises
    ------
    InputError
        When the ``[recipe]`` table, its ``name`` or its ``measurement`` is missing or not a string.
    """
    path = Path(path)
    head = data.get("recipe")
    if not isinstance(head, dict):
        raise InputError("recipe section missing", file=path, field="recipe", expected="a [recipe] table",
                         got=head)
    for key in ("name", "measurement"):
        if key not in head:
            raise InputError("recipe key missing", file=path, field=f"recipe.{key}")
        if not isinstance(head[key], str):
            raise InputError("recipe value of the wrong type", file=path, field=f"recipe.{key}", expected="str",
                             got=head[key])
    return RecipeHead(head["name"], (path.parent / head["measurement"]).resolve())


def read_recipe_head(path: str | Path) -> RecipeHead:
    """The name and measurement folder of a recipe file.

    Parameters
    ----------
    path : str or Path
        The recipe's TOML file.

    Returns
    -------
    RecipeHead
        The recipe's name and its measurement folder (an absolute path).

    Raises
    ------
    InputError
        When the file is missing, is no TOML, or its head is faulty (:func:`recipe_head`).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("recipe not found", file=path, expected="a TOML recipe file")
    return recipe_head(read_toml(path, expected="a TOML recipe file"), path)
