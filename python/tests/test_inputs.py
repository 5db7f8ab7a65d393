"""Images in: the size is checked from the shape before anything is copied, a copy (any layout, any
colour order) is made with the GIL released, and ``channels="bgr"`` reads OpenCV's colour order."""

from __future__ import annotations

import time

import numpy as np
import pytest

import clatch
from helpers import ASTRONAUT, synthetic
from test_threads import longest_stall

#: 21 megapixels, a 5616 x 3744 photo.
H, W = 3744, 5616


def test_the_size_is_checked_from_the_shape_before_any_copy(backend):
    """Finding P1: a broadcast array of 10^9 pixels was copied (15-18 s, 1 GB, the GIL held)
    before ImageTooLarge; now the shape alone refuses it."""
    extractor = clatch.Extractor(backend)
    huge = [
        np.broadcast_to(np.uint8(7), (1, 10**9)),
        np.broadcast_to(np.uint8(7), (1, 2 * 10**8, 3)),
        np.broadcast_to(np.uint8(7), (100_000, 100_000)),
        np.broadcast_to(np.uint8(7), (100_000, 100_000, 4))[::-1],
    ]
    calls = [extractor.detect, extractor.detect_and_describe, clatch.to_gray]
    for image in huge:
        for call in calls + [lambda i: extractor.detect_and_describe_batch([np.zeros((100, 100), np.uint8), i])]:
            start = time.perf_counter()
            with pytest.raises(clatch.InvalidInputError) as info:
                call(image)
            seconds = time.perf_counter() - start
            assert seconds < 0.2, f"{seconds:.1f} s to refuse shape {image.shape}: it was copied first"
            assert info.value.kind == "ImageTooLarge"
            assert f"of shape {image.shape}" in str(info.value)


def layouts():
    """A 21 MP image in every layout that needs a copy, and the one read in place."""
    rng = np.random.default_rng(3)
    gray = rng.integers(0, 256, size=(W, H), dtype=np.uint8)
    rgb = rng.integers(0, 256, size=(H, W, 3), dtype=np.uint8)
    return {
        "gray transposed": gray.T,
        "gray column step": np.repeat(gray.T, 2, axis=1)[:, ::2],
        "rgb": rgb,
        "rgb negative strides": rgb[::-1, ::-1],
        "bgr fortran order": np.asfortranarray(rgb[..., ::-1]),
        "rgba": np.concatenate([rgb, rgb[..., :1]], axis=-1),
        "gray in place": gray,
    }


@pytest.fixture(scope="module")
def big_images():
    return layouts()


@pytest.mark.parametrize("layout", [
    "gray transposed", "gray column step", "rgb", "rgb negative strides", "bgr fortran order", "rgba", "gray in place"
])
def test_no_layout_holds_the_gil(big_images, layout):
    """Finding P1: a transposed 21 MP image blocked every other Python thread for 160-200 ms while
    it was copied. Now every conversion runs with the GIL released: another thread, spinning,
    is never stalled for more than a few switch intervals (5 ms each) however long the call."""
    image = big_images[layout]
    keywords = {"channels": "bgr"} if layout.startswith("bgr") else {}
    call = lambda: clatch.to_gray(image, **keywords)  # noqa: E731
    # Held, the GIL stalls the other thread for the whole conversion (50-850 ms here, 85-99 % of the
    # call). Released, the stall is a switch interval or the operating system's scheduling on a busy
    # machine (ticks of 4 ms: 2-25 ms seen on 2 loaded cores), so the best of five runs is compared
    # with the call's length, not with 5 ms.
    # A call shorter than a few switch intervals may pass whole before the other thread runs: a
    # stall under 6 ms passes whatever the call's length.
    runs = [longest_stall(call) for _ in range(5)]
    passed = [(stall, seconds) for stall, seconds in runs if stall < max(0.3 * seconds, 0.006) and stall < 0.1]
    assert passed, f"{layout}: another thread stalled " + ", ".join(f"{a * 1000:.1f} ms of a {b * 1000:.1f} ms call" for a, b in runs)


def test_every_layout_gives_the_same_gray(big_images):
    expected = clatch.to_gray(big_images["rgb"])
    assert np.array_equal(clatch.to_gray(big_images["rgb negative strides"]), expected[::-1, ::-1])
    assert np.array_equal(clatch.to_gray(big_images["bgr fortran order"], channels="bgr"), expected)
    assert np.array_equal(clatch.to_gray(big_images["rgba"]), expected)
    assert np.array_equal(clatch.to_gray(big_images["gray transposed"]), big_images["gray transposed"])
    assert np.array_equal(clatch.to_gray(big_images["gray column step"]), big_images["gray transposed"])


def test_bgr_from_opencv_gives_the_gray_images_keypoints(backend):
    """Finding P9: ``cv2.imread`` gives BGR, which was read as RGB. ``channels="bgr"`` gives exactly
    what the RGB image gives (and its gray image gives), and the gray image of cv2.cvtColor but for
    rounding (OpenCV 5 rounds its weights otherwise than 4.x, whose integer weights the library
    uses: at most 1 apart)."""
    cv2 = pytest.importorskip("cv2")
    rgb = synthetic(480, 640, 21, channels=3)
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    gray = clatch.to_gray(rgb)
    assert np.array_equal(clatch.to_gray(bgr, channels="bgr"), gray)
    cv2_gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    assert np.abs(cv2_gray.astype(np.int16) - gray).max() <= 1
    assert np.abs(clatch.to_gray(bgr).astype(np.int16) - gray).max() > 10, "colours that tell the orders apart"
    extractor = clatch.Extractor(backend, max_keypoints=800)
    expected_k, expected_d = extractor.detect_and_describe(gray)
    assert len(expected_k) > 100
    for image, channels in ((bgr, "bgr"), (rgb, "rgb")):
        k, d = extractor.detect_and_describe(image, channels=channels)
        assert np.array_equal(k, expected_k) and np.array_equal(d, expected_d)
        assert np.array_equal(extractor.detect(image, channels=channels), expected_k)
        [(kb, db)] = extractor.detect_and_describe_batch([image], channels=channels)
        assert np.array_equal(kb, expected_k) and np.array_equal(db, expected_d)
        described = extractor.describe(image, expected_k[:50], channels=channels)
        assert np.array_equal(described[1], extractor.describe(gray, expected_k[:50])[1])
    k, _ = extractor.detect_and_describe(bgr)  # read as RGB: other pixels, other keypoints
    assert not np.array_equal(k, expected_k)


def test_channels_must_be_named():
    image = synthetic(100, 100, 1, channels=3)
    for bad in ("BGR", "gray", ""):
        with pytest.raises(clatch.InvalidInputError) as info:
            clatch.to_gray(image, channels=bad)
        assert info.value.kind == "InvalidConfig" and '"rgb", "bgr"' in str(info.value)
    with pytest.raises(clatch.ArgumentTypeError):
        clatch.to_gray(image, channels=None)
    gray = clatch.imread(ASTRONAUT)
    assert np.array_equal(clatch.to_gray(gray, channels="bgr"), gray)  # a gray image has no order
