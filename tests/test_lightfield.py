import numpy as np
import pytest
import torch

from lfstream.errors import LFShapeError, LFValueError
from lfstream.lightfield import (
    aperture_weights,
    as_float,
    centre_view,
    crop_views,
    dof_image,
    downsample_angular,
    from_mosaic,
    from_sensor,
    read_only,
    to_mosaic,
    to_sensor,
    to_uint8,
)
from tests.conftest import random_lf


def test_centre_view_is_u_half_v_half(rng):
    lf = random_lf(rng, (4, 5, 6, 7, 3))
    np.testing.assert_array_equal(centre_view(lf), lf[2, 2])
    video = np.stack([lf, lf[::-1]])
    np.testing.assert_array_equal(centre_view(video)[1], lf[::-1][2, 2])


def test_sensor_follows_eq_2_4(rng):
    # Lp(u + s*N, v + t*N) = L(s, t, u, v) in 0-based form, N = views per axis.
    lf = random_lf(rng, (3, 4, 5, 6, 3))
    sensor = to_sensor(lf)
    assert sensor.shape == (5 * 3, 6 * 4, 3)
    for s, t, u, v in [(0, 0, 0, 0), (2, 5, 1, 3), (4, 1, 2, 0)]:
        np.testing.assert_array_equal(sensor[u + s * 3, v + t * 4], lf[u, v, s, t])


def test_round_trips_numpy_and_torch(rng):
    lf = random_lf(rng, (2, 3, 5, 4, 6, 3))  # a video
    for x in (lf, torch.from_numpy(lf)):
        back = from_sensor(to_sensor(x), (3, 5))
        assert type(back) is type(x)
        np.testing.assert_array_equal(np.asarray(back), lf)
        back = from_mosaic(to_mosaic(x), (3, 5))
        np.testing.assert_array_equal(np.asarray(back), lf)


def test_mosaic_tiles_views_side_by_side(rng):
    lf = random_lf(rng, (2, 3, 4, 5, 3))
    m = to_mosaic(lf)
    np.testing.assert_array_equal(m[4:8, 10:15], lf[1, 2])


def test_crop_keeps_centre(rng):
    lf = random_lf(rng, (9, 9, 4, 4, 3))
    c = crop_views(lf, 7)
    assert c.shape[:2] == (7, 7)
    np.testing.assert_array_equal(centre_view(c), centre_view(lf))
    lf14 = random_lf(rng, (14, 14, 2, 2, 3))
    np.testing.assert_array_equal(centre_view(crop_views(lf14, 7)), centre_view(lf14))
    with pytest.raises(LFValueError):
        crop_views(lf, 10)


def test_downsample_angular_averages_blocks(rng):
    lf = random_lf(rng, (4, 4, 3, 3, 3))
    d = downsample_angular(lf, 2)
    assert d.shape == (2, 2, 3, 3, 3)
    expect = lf[2:4, 0:2].astype(np.float32).mean(axis=(0, 1)) / 255
    np.testing.assert_allclose(d[1, 0], expect, atol=1e-6)
    dt = downsample_angular(torch.from_numpy(lf), 2)
    np.testing.assert_allclose(dt.numpy(), d, atol=1e-6)


def test_dof_image_full_aperture_and_pinhole(rng):
    lf = random_lf(rng, (5, 5, 6, 6, 3))
    np.testing.assert_allclose(dof_image(lf), as_float(lf).mean(axis=(0, 1)), atol=1e-6)
    pin = aperture_weights((5, 5), radius=0)
    np.testing.assert_allclose(dof_image(lf, pin), as_float(lf[2, 2]), atol=1e-6)
    circ = aperture_weights((5, 5), radius=1)
    assert circ.sum() == 5  # centre + 4 neighbours
    t = dof_image(torch.from_numpy(lf), torch.from_numpy(circ))
    np.testing.assert_allclose(t.numpy(), dof_image(lf, circ), atol=1e-6)
    with pytest.raises(LFValueError):
        dof_image(lf, np.zeros((5, 5)))
    with pytest.raises(LFShapeError):
        dof_image(lf, np.ones((3, 3)))


def test_uint8_float_boundary():
    x = np.array([0, 1, 127, 128, 255], np.uint8)
    np.testing.assert_array_equal(to_uint8(as_float(x)), x)
    assert to_uint8(np.array([-1.0, 2.0, np.nan])).tolist() == [0, 255, 0]


@pytest.mark.parametrize("bad", [np.zeros((5, 5, 3)), np.zeros((2, 2, 0, 4, 3)), np.zeros((2, 2, 4, 4, 5)), [1, 2]])
def test_bad_shapes_raise(bad):
    with pytest.raises(LFShapeError):
        centre_view(bad)


def test_view_offsets_follow_the_convention_and_the_view_axes():
    from lfstream.lightfield import view_offsets

    off = view_offsets((3, 5))
    assert off.shape == (3, 5, 2) and off.dtype == np.float32
    assert off[1, 2].tolist() == [0.0, 0.0]  # the centre view does not move
    assert off[0, 4].tolist() == [-1.0, 2.0]  # (u - u0, v - v0)
    axes = np.array([[-1.1, -0.05], [0.02, 0.9]])
    assert np.allclose(view_offsets((3, 5), axes)[0, 4], axes @ [-1.0, 2.0], atol=1e-6)
    assert np.array_equal(view_offsets((3, 5), np.eye(2)), off)
    with pytest.raises(LFValueError, match="axes"):
        view_offsets((3, 5), np.full((2, 2), np.nan))


def test_read_only_is_a_view_that_leaves_the_array_writable():
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    ro = read_only(a)
    assert np.shares_memory(ro, a) and ro.shape == a.shape and ro.dtype == a.dtype  # no copy
    assert not ro.flags.writeable and a.flags.writeable
    with pytest.raises(ValueError):
        ro[0, 0] = 1.0
    a[0, 0] = 5.0  # the caller's array is untouched and still its to write
    assert ro[0, 0] == 5.0
    assert not read_only(ro).flags.writeable  # idempotent on read-only input


@pytest.mark.parametrize("views", [(7, 7), (8, 6), (5, 9)])
@pytest.mark.parametrize("axes", [np.eye(2), np.diag([-1.0, 1.0]), np.diag([1.0, -1.0]), -np.eye(2),
                                  np.array([[0.0, 1.0], [1.0, 0.0]]), np.array([[0.0, -1.0], [1.0, 0.0]]),
                                  np.array([[0.0, 1.0], [-1.0, 0.0]])])
def test_canonical_views_reorder_a_flipped_or_swapped_grid_to_the_convention(views, axes):
    """Each view of a grid with ``axes`` holds its own displacement (view_offsets); reordered,
    every view holds the convention's displacement for its new index, the centre view stays
    the centre (an even axis that is reversed loses one end view), and nothing is copied."""
    from lfstream.lightfield import canonical_views, view_offsets

    shift = view_offsets(views, axes)
    lf = np.zeros((*views, 1, 1, 3), np.float32)
    lf[..., 0, 0, :2] = shift
    present = np.ones(views, bool)
    present[0, 0] = False
    out, mask = canonical_views(lf, axes, present)
    u, v = out.shape[:2]
    assert np.array_equal(out[:, :, 0, 0, :2], view_offsets((u, v)))
    assert out.base is not None or out is lf  # a view of the input, no copy
    assert mask.shape == (u, v) and (~mask).sum() <= 1
    a, b = views
    shorter = (a - (a % 2 == 0), b - (b % 2 == 0))  # a reversed even axis loses one end view
    assert sorted((u, v)) in ([*sorted((a, b))], sorted((shorter[0], b)), sorted((a, shorter[1])), sorted(shorter))


def test_canonical_views_leave_the_convention_and_no_axes_as_they_are():
    from lfstream.lightfield import canonical_views

    lf = np.zeros((2, 5, 5, 4, 4, 3), np.uint8)  # a video: the view axes are the second and third
    assert canonical_views(lf, None)[0] is lf and canonical_views(lf, np.eye(2))[0].shape == lf.shape
    assert canonical_views(lf, np.diag([-1.0, 1.0]))[0].shape == lf.shape
    with pytest.raises(LFValueError, match="axes"):
        canonical_views(lf, np.ones(3))


def test_check_unit_range_clips_overshoot_and_refuses_other_units():
    from lfstream.lightfield import FLOAT_RANGE_SLACK, check_unit_range

    check_unit_range(np.full((3, 3), 255, np.uint8))  # 8-bit levels
    check_unit_range(np.array([-0.02, 0.5, 1.03], np.float32))  # resampling overshoot
    check_unit_range(np.array([-FLOAT_RANGE_SLACK, 1.0 + FLOAT_RANGE_SLACK]))
    check_unit_range(np.zeros((0, 3), np.float32))
    for bad in (np.array([0.0, 255.0], np.float32), np.array([-1.5, 0.5])):
        with pytest.raises(LFValueError, match=r"frame 3: float values span .* divide by 255"):
            check_unit_range(bad, "frame 3")
    # another integer type's scale is a guess (8-bit levels in int64 were read as floats and
    # saturated to white): refused, naming the frame, empty or not
    for dtype in (np.int64, np.int16, np.uint16, bool):
        for shape in ((3, 3), (0, 3)):
            with pytest.raises(LFValueError, match=rf"frame 3: {np.dtype(dtype).name} samples; expected uint8"):
                check_unit_range(np.zeros(shape, dtype), "frame 3")


def test_to_uint8_refuses_other_integer_samples():
    import torch

    for bad in (np.arange(3, dtype=np.int64), np.ones(3, np.uint16), np.ones(3, bool), torch.arange(3)):
        with pytest.raises(LFValueError, match="samples; expected uint8, or float in"):
            to_uint8(bad)
    assert to_uint8(torch.tensor([0.0, 0.5, 1.0])).tolist() == [0, 128, 255]
