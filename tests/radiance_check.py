"""Radiance's own reading of a BSDF XML file (pyradiance, a test dependency): the independent check of the files
bsdfkit writes and reads."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

_RADIANCE = """
import json, sys
import pyradiance.bsdf as rb
sd = rb.load_file(sys.argv[1])
flags = {"reflection": rb.SAMPLE_ALL & ~rb.SAMPLE_T, "transmission": rb.SAMPLE_ALL & ~rb.SAMPLE_R}
out = {side: {"front": [rb.direct_hemi(sd, 180.0 - float(t), 0.0, f) for t in sys.argv[2:]],
              "back": [rb.direct_hemi(sd, float(t), 0.0, f) for t in sys.argv[2:]],
              # the incident patch at Klems azimuth 0, bsdfkit's plane of incidence (an anisotropic file differs)
              "front_phi180": [rb.direct_hemi(sd, 180.0 - float(t), 180.0, f) for t in sys.argv[2:]]}
       for side, f in flags.items()}
out["mirror_over_opposite"] = rb.query(sd, 150.0, 0.0, 150.0, 180.0)[1] / rb.query(sd, 150.0, 0.0, 150.0, 0.0)[1]
print(json.dumps(out))
"""


def radiance_direct_hemi(path, thetas):
    """Radiance's direct-hemispherical values (pyradiance) per side, front and back, at incidences [deg]; in a
    fresh interpreter: pyradiance's C library keeps a global BSDF cache that must not outlive a test."""
    pytest.importorskip("pyradiance.bsdf")
    done = subprocess.run([sys.executable, "-c", _RADIANCE, str(path), *map(str, thetas)], capture_output=True,
                          text=True, timeout=120, check=True)
    return json.loads(done.stdout)
