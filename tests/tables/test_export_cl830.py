"""Acceptance: the measured (reconstructed) cl830 bibs table survives export → read with its TIS intact."""
import pytest

from bsdfkit.tables import export


@pytest.mark.parametrize("fmt,suffix", [("tracepro", "txt"), ("zemax", "bsdf")])
@pytest.mark.parametrize("side", ["reflection", "transmission"])
def test_cl830_bibs_round_trip(bundled_scan, tmp_path, fmt, suffix, side):
    path = tmp_path / f"bibs.{suffix}"
    result = export.export(bundled_scan, fmt, "bibs", side, path)
    summary = export.read_any(path)
    assert summary.format == fmt and summary.incidences_deg == [5.0, 45.0, 56.0]
    for k, source in enumerate(result.tis_source[side]):
        assert summary.tis_computed[side][k] == pytest.approx(source, rel=5e-3)
    # the source TIS is the reconstruction's own hemispherical integral: close to the scan's TIS table
    assert 0.04 < min(result.tis_source[side]) and max(result.tis_source[side]) < 0.13
