"""The BSDF dataset schema (bsdfkit.measurement.schema) against docs/architecture.md and the readers' outputs."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from bsdfkit.core.errors import ValidationError
from bsdfkit.measurement import schema
from bsdfkit.measurement.table import read_table
from bsdfkit.tables.to_dataset import ingest

ROOT = Path(__file__).resolve().parents[2]
DOC = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
DATA = ROOT / "tests" / "data"


def _section(title: str) -> str:
    start = DOC.index(title)
    end = DOC.find("\n## ", start + 1)
    return DOC[start: end if end >= 0 else None]


def _schema_rows() -> list[dict[str, str]]:
    lines = [ln for ln in _section("## The calibrated BSDF dataset").splitlines() if ln.startswith("|")]
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    return [dict(zip(header, (c.strip() for c in ln.strip("|").split("|")))) for ln in lines[2:]]


def test_documented_schema_table_is_the_schema_module():
    documented = [(r["name"].strip("`"), r["kind"], r["dims"], r["units"], r["type"], r["required"])
                  for r in _schema_rows()]
    declared = [(v.name, "coord" if v.coord else "data", ", ".join(v.dims), v.units or "–", v.type,
                 "yes" if v.required else "no") for v in schema.VARIABLES]
    assert documented == declared


def test_documented_dims_and_attributes_are_the_schema_module():
    section = _section("## The calibrated BSDF dataset")
    dims = re.search(r"Dimensions: (.*?)\. Variables", section, re.S).group(1)
    assert re.findall(r"`(\w+)`", dims) == list(schema.DIMS)
    attrs = re.search(r"Attributes \(all required\): (.*?); fixed values (.*?); `side`", section, re.S)
    assert re.findall(r"`(\w+)`", attrs.group(1)) == list(schema.ATTRIBUTES)
    assert dict(re.findall(r'`(\w+) = "([^"]*)"`', attrs.group(2))) == schema.FIXED_ATTRIBUTES


def _layout_entries() -> dict[str, str]:
    """The entries of the package-layout block: ``"api.py"`` or ``"tables/"`` → its text (continuation lines)."""
    block = _section("## Package layout").split("```")[1]
    entries: dict[str, str] = {}
    current = None
    for line in block.splitlines():
        m = re.match(r"^  (\S+?)(/|\.py)\s", line + " ")
        if m:
            current = m.group(1) + m.group(2)
            entries[current] = line
        elif current is not None:
            entries[current] += "\n" + line
    return entries


def test_every_module_of_the_package_is_named_in_the_architecture_doc():
    entries = _layout_entries()
    missing = []
    for path in sorted((ROOT / "bsdfkit").rglob("*.py")):
        parts = path.relative_to(ROOT / "bsdfkit").parts
        if len(parts) == 1:
            named = parts[0] in entries
        elif path.name == "__init__.py":
            named = parts[0] + "/" in entries  # a subpackage is named by its folder
        else:
            entry = entries.get(parts[0] + "/", "")
            named = (re.search(rf"(?<![\w.]){re.escape(path.stem)}(?!\w)", entry) is not None
                     and all(folder + "/" in entry for folder in parts[1:-1]))
        if not named:
            missing.append("/".join(parts))
    assert not missing, f"modules missing from docs/architecture.md 'Package layout': {missing}"


@pytest.fixture(scope="module")
def table_dataset(tmp_path_factory):
    path = tmp_path_factory.mktemp("schema") / "t.csv"
    path.write_text("theta_i,theta_s,brdf\n" + "".join(f"10,{t},{0.3 + 0.01 * t}\n" for t in range(-80, 81, 10)))
    return read_table(path)


@pytest.mark.parametrize("source", [
    "ansys-radiant-zemax-bsdf/radiant_imaging_sphere_planesymmetric_BRDF.bsdf",
    "radiance-bsdf2klems/lambertian_r030_t060_klems_full.xml",
    "golden/zemax_asymmetric_btdf.bsdf",
])
def test_vendor_files_give_valid_datasets(source):
    ds = ingest(DATA / source)
    assert schema.validate_bsdf_dataset(ds) is ds
    assert ds["incident_band"].attrs["units"] == "nm" and ds["exposure"].attrs["units"] == "s"


def test_calibrated_scan_and_table_are_valid(bundled_scan, table_dataset):
    for ds in (bundled_scan, table_dataset):
        assert ds.bsdf.validate() is ds
        for var in schema.VARIABLES:
            if var.units is not None and var.name in ds.variables:
                assert ds[var.name].attrs["units"] == var.units, var.name
    assert "below_dark" in bundled_scan and "below_dark" not in table_dataset


@pytest.mark.parametrize(("change", "field", "expected"), [
    (lambda ds: ds.drop_vars("bsdf_std"), "bsdf_std", "float on (record, wavelength)"),
    (lambda ds: ds.assign(bsdf=ds["bsdf"].T), "bsdf", "(record, wavelength)"),
    (lambda ds: ds.assign(grazing=ds["grazing"].astype(float)), "grazing", "bool"),
    (lambda ds: ds.assign_attrs(frame="instrument"), "frame", "'sample'"),
    (lambda ds: ds.drop_attrs(deep=False), "quantity", "the attributes"),
    (lambda ds: ds.assign_coords(side=("record", np.where(ds["side"].values == "reflection", "front", "back")
                                       .astype(object))), "side", "reflection or transmission"),
])
def test_validation_refuses_in_one_line_naming_the_field(table_dataset, change, field, expected):
    with pytest.raises(ValidationError) as info:
        schema.validate_bsdf_dataset(change(table_dataset))
    text = str(info.value)
    assert "\n" not in text and f"field '{field}'" in text and f"expected {expected}" in text


def test_other_units_are_refused(table_dataset):
    ds = table_dataset.copy()
    ds["theta_s"] = ds["theta_s"].copy()
    ds["theta_s"].attrs["units"] = "rad"
    with pytest.raises(ValidationError, match=r"field 'theta_s': not a BSDF dataset: variable in other units; "
                                              r"expected units 'deg', got 'rad'"):
        ds.bsdf.validate()
