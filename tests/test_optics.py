"""Seed chapter 2: SPC <-> camera array, refocus distance and DoF (Table 2.1), vignetting,
and the seahorse sample checked against the geometry."""

import json
import math

import numpy as np
import pytest
import torch

from lfstream.cli import main
from lfstream.errors import LFValueError
from lfstream.optics import (
    PlenopticCamera,
    apply_vignetting,
    camera_array,
    main_lens_vignetting,
    mla_vignetting,
    plenoptic_camera,
    radial_falloff,
    refocus_plane,
    slope_for_distance,
)
from tests.conftest import shared, shifted_views

# Seed Table 2.1 (F = 100 mm, f/2, 500 x 500 microlenses, focused at infinity): (N, a, near, far)
TABLE_2_1 = [(25, 0.1, 13.6, 35.7), (25, 0.2, 8.1, 13.2), (25, 0.3, 5.7, 8.1), (25, 0.4, 4.5, 5.9), (5, 0.4, 11.6, 82.5)]


def within_table(model: float, table: float) -> bool:
    """1 %, or the table's own printing precision (0.1 m) where that is wider."""
    return abs(model - table) <= max(0.01 * table, 0.05 + 1e-3)


def test_worked_example_camera_array():
    arr = camera_array(PlenopticCamera(focal_length_mm=100, f_number=2, microlenses=500, pixels_per_lens=25))
    assert arr.cameras == (25, 25) and arr.camera_resolution == (500, 500)
    assert arr.camera_aperture_mm == pytest.approx(2.0) and arr.camera_focal_length_mm == pytest.approx(4.0)
    assert arr.camera_fov_deg == pytest.approx(math.degrees(2 * math.atan(50 / 200)))
    pos = np.array(arr.positions_mm)
    assert pos.shape == (25, 25, 2) and np.allclose(pos.mean(axis=(0, 1)), 0)  # centred on the main lens
    assert pos[12, 12].tolist() == [0, 0] and pos[0, 0].tolist() == [-24, -24]
    back = plenoptic_camera(arr)
    assert (back.focal_length_mm, back.f_number, back.microlenses, back.pixels_per_lens) == (100, 2, 500, 25)


@pytest.mark.parametrize("n,a,near,far", TABLE_2_1)
def test_table_2_1_dof_borders(n, a, near, far):
    plane = refocus_plane(PlenopticCamera(100, 2, 500, n), a)
    assert within_table(plane.dof_near_m, near), plane
    assert within_table(plane.dof_far_m, far), plane
    assert plane.dof_near_m < plane.focus_m < plane.dof_far_m


def test_table_2_1_refocus_distance():
    # N = 5, a = 0.4 focuses at 25.0 m (the table's N = 25 "point of focus" column is the
    # midpoint of its borders, not a focus distance, and is not tested)
    assert refocus_plane(PlenopticCamera(100, 2, 500, 5), 0.4).focus_m == pytest.approx(25.0, rel=0.01)


def test_slope_distance_inverse_and_limits():
    spc = PlenopticCamera(100, 2, 500, 5)
    for d in (5.2, 9.2, 14.2, 40.0):
        assert refocus_plane(spc, slope_for_distance(spc, d)).focus_m == pytest.approx(d, rel=1e-6)
    assert math.isinf(refocus_plane(spc, 0.0).focus_m)  # focused at infinity
    assert math.isinf(refocus_plane(spc, -0.3).focus_m)  # beyond infinity
    with pytest.raises(LFValueError):
        refocus_plane(spc, float("nan"))
    with pytest.raises(LFValueError):
        PlenopticCamera(100, 0, 500, 5)


def test_optics_cli_json(capsys):
    code = main(["optics", "--focal-length", "100", "--f-number", "2", "--microlenses", "500",
                 "--pixels-per-lens", "5", "--slope", "0.4", "0", "--alpha", "1.25", "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    arr = out["camera_array"]
    assert arr["cameras"] == [5, 5] and arr["camera_resolution"] == [500, 500]
    assert arr["camera_aperture_mm"] == pytest.approx(10) and arr["camera_focal_length_mm"] == pytest.approx(20)
    assert {"camera_fov_deg", "positions_mm"} <= set(arr)
    r = out["refocus"]
    assert [set(p) for p in r] == [{"slope", "alpha", "focus_m", "dof_near_m", "dof_far_m"}] * 3
    assert r[0]["focus_m"] == pytest.approx(25.1, abs=0.1) and r[1]["focus_m"] is None
    assert r[2]["slope"] == pytest.approx(0.2)


def test_vignetting_masks():
    views, size = (7, 7), (12, 16)
    mla = mla_vignetting(views, size, r=3.2, a=40.0)  # near-hard disc of radius 3.2 pixels
    assert mla.shape == (7, 7, 12, 16)
    assert mla[0, 0].max() < 1e-3 and mla[6, 6].max() < 1e-3  # corner views removed
    assert mla[3, 3].min() == pytest.approx(1.0) and mla[3, 0].min() > 0.5
    main_lens = main_lens_vignetting(views, size, r=0.8, a=2.0)
    assert main_lens.min() > 0.2  # no view removed ...
    assert main_lens[:, :, 6, 8].std() < 0.05  # ... every view sees about the same falloff at its centre
    assert main_lens[3, 3, 6, 8] > main_lens[3, 3, 0, 0]  # darker towards each view's corner
    lf = np.full((7, 7, 12, 16, 3), 200, np.uint8)
    out = apply_vignetting(lf, mla)
    np.testing.assert_allclose(out[..., 0], mla * 200 / 255, atol=1e-6)  # Hadamard product, no reshape
    t = apply_vignetting(torch.from_numpy(lf), main_lens)
    np.testing.assert_allclose(t.numpy(), apply_vignetting(lf, main_lens), atol=1e-6)
    assert radial_falloff(0.0, 1.0, 2.0) == 1.0
    assert radial_falloff(1.7, 1.7, 3.0) == pytest.approx(0.5)  # half transmission at r
    assert radial_falloff(1e6, 1.0, 50.0) == 0.0  # no overflow warning, no NaN


# ----------------------------------------------------------------------------------------
# The seahorse sample, rendered by the seed's author with this camera


SEAHORSE_SPC = PlenopticCamera(focal_length_mm=100, f_number=2, microlenses=500, pixels_per_lens=5)
BANDS = [(y, y + 20) for y in range(160, 390, 20)]  # rows of the column of seahorses, far (top) to near
COLUMN = slice(215, 285)


@pytest.fixture(scope="module")
def seahorse():
    from lfstream import read_lf

    return read_lf(shared("seahorse5x5", "camImagesFlat"))


def _band_slopes(lf) -> np.ndarray:
    """Disparity of each band of the seahorse column by photo-consistency over the centre row and column."""
    idx = [(2, k) for k in range(5)] + [(k, 2) for k in range(5) if k != 2]
    slopes = np.round(np.arange(0.3, 2.5, 0.02), 3)
    costs = np.array([[v[:, y0:y1, COLUMN].var(axis=0).mean() for y0, y1 in BANDS]
                      for v in (shifted_views(lf, idx, s).mean(-1) for s in slopes)])
    return slopes[np.argmin(costs, axis=0)]


def _sharpness(img: np.ndarray) -> np.ndarray:
    g = img.astype(np.float32).mean(-1)
    grad = np.abs(np.diff(g, axis=0))[:, :-1] + np.abs(np.diff(g, axis=1))[:-1, :]
    return np.array([grad[y0:y1, COLUMN].mean() for y0, y1 in BANDS])


def test_seahorse_disparities_match_the_geometry(seahorse):
    """The data agrees with the camera geometry: converting each band's measured disparity to
    a distance with the thin-lens ray model spans seahorse 0 (5.2 m, bottom) to seahorse 9
    (14.2 m, top) within the ±0.5 m of a distance judged by eye, monotonically."""
    slopes = _band_slopes(seahorse)
    dist = np.array([refocus_plane(SEAHORSE_SPC, s).focus_m for s in slopes])
    assert np.all(np.diff(dist) <= 0.3), dist  # top (far) to bottom (near), allowing band overlap
    assert dist[0] == pytest.approx(14.2, abs=0.5) and dist[-1] == pytest.approx(5.2, abs=0.5), dist


def test_seahorse_focus_moves_near_to_far_and_dof_at_a_04(seahorse):
    """Refocusing over a sweep of shifts: the sharpest seahorse moves from near (bottom) to
    far (top) as the focus distance grows. At a = 0.4 (Table 2.1, N = 5: DoF 11.6-82.5 m),
    the seahorses the geometry puts inside the depth of field (>= 11.6 + 0.5 m) are all
    sharper, relative to their own best focus, than those it puts outside (< 11.6 - 0.5 m)."""
    from lfstream.refocus import focal_stack

    distances = [6.0, 7.5, 9.0, 11.0, 13.5]
    slopes = [slope_for_distance(SEAHORSE_SPC, d) for d in distances] + [0.4]
    stack = focal_stack(seahorse, slopes=slopes)
    sharp = np.array([_sharpness(img) for img in stack])  # (planes, bands)
    sweep = sharp[: len(distances)]
    best_band = np.argmax(sweep / sweep.max(axis=0), axis=1)
    assert np.all(np.diff(best_band) <= 0) and best_band[0] > best_band[-1], best_band
    band_dist = np.array([refocus_plane(SEAHORSE_SPC, s).focus_m for s in _band_slopes(seahorse)])
    plane = refocus_plane(SEAHORSE_SPC, 0.4)
    rel = sharp[-1] / sharp.max(axis=0)
    inside = band_dist >= plane.dof_near_m + 0.5
    outside = band_dist < plane.dof_near_m - 0.5
    assert inside.any() and outside.any()
    assert rel[inside].min() > rel[outside].max(), (band_dist, rel)
