"""The transformers of the geo-objects' local frames (``spatial.local_frame``, one per whole-degree meridian): the
second and later meridians are made from the first one's PROJ pipeline, and must transform exactly as a search of
PROJ's database would (each to the last bit, both ways)."""

import threading

import numpy as np
import pytest
from pyproj import Transformer

from tollcli import spatial


@pytest.mark.parametrize("inverse", [False, True])
def test_local_frames_from_the_learnt_pipeline_transform_as_proj_would(inverse):
    rng = np.random.default_rng(5)
    out = {}

    def run():  # a thread of its own: an empty cache, the first frame searched, the others from its pipeline
        for meridian in (10, 11, -3, 0, 179, -180):
            crs = spatial.local_frame(meridian)
            ours = spatial._transformer(crs, inverse)
            theirs = Transformer.from_crs(*(("EPSG:4326", crs) if not inverse else (crs, "EPSG:4326")), always_xy=True)
            lon, lat = meridian + rng.uniform(-1.5, 1.5, 5000), rng.uniform(-80, 80, 5000)
            if inverse:
                lon, lat = theirs.transform(lon, lat, direction="INVERSE")  # metres in the frame
            out[meridian] = (ours.transform(lon, lat), theirs.transform(lon, lat), ours.definition)
        out["learnt"] = spatial._TRANSFORMERS.__dict__.get("local_pipelines", {}).get(inverse)

    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    assert out["learnt"] is not None and "{meridian}" in out["learnt"]  # the later frames did come from the template
    for meridian in (10, 11, -3, 0, 179, -180):
        (ox, oy), (tx, ty), definition = out[meridian]
        assert np.array_equal(ox, tx) and np.array_equal(oy, ty), meridian
        assert f"lon_0={((meridian + 180) % 360) - 180} " in definition


def test_a_frame_that_is_not_a_local_one_is_searched_as_before():
    ours = spatial._transformer("EPSG:32633")
    x, y = ours.transform(15.0, 52.0)
    assert abs(x - 500000.0) < 1e-6 and 5.7e6 < y < 5.8e6
