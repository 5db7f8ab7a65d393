"""Bit-equality with the command-line tool: ``clatch extract IMG -o PREFIX`` writes the keypoints as
CSV (x, y, size, angle, response, octave) and the descriptors as ``.npy`` (OpenCV LATCH byte order);
the package must return the very same keypoints and bytes for the same image and settings."""

from __future__ import annotations

import numpy as np
import pytest

import clatch
from helpers import ASTRONAUT, run_extract, synthetic, write_pnm

# (command-line flags, the same settings as Extractor keywords)
SETTINGS = [
    ([], {}),
    (["--single-scale"], {"single_scale": True}),
    (["--bits", "256", "--threshold", "30", "--max-keypoints", "700"], {"bits": 256, "threshold": 30, "max_keypoints": 700}),
    (["--pyramid", "3:2", "--grid", "4"], {"pyramid": (3, 2.0), "grid": 4}),
    (["--ranking", "harris", "--level-budget", "global", "--subpixel", "none"], {"ranking": "harris", "level_budget": "global", "subpixel": "none"}),
    (["--single-scale", "--smoothing", "binomial5", "--keypoint-size", "48", "--bits", "72"], {"single_scale": True, "smoothing": "binomial5", "keypoint_size": 48.0, "bits": 72}),
]
IDS = ["default", "single-scale", "bits256-threshold30", "pyramid3x2-grid4", "harris-global-whole", "smooth5-size48-bits72"]


def assert_same(table: np.ndarray, descriptors: np.ndarray, keypoints: np.ndarray, ours: np.ndarray) -> None:
    assert len(table) > 0, "the tool found no keypoints: the comparison would be empty"
    assert keypoints.dtype == clatch.KEYPOINT_DTYPE
    assert len(keypoints) == len(table)
    for col, name in enumerate(["x", "y", "size", "angle", "response"]):
        expected = table[:, col].astype(np.float32)
        got = keypoints[name]
        assert np.array_equal(got, expected), f"{name}: {np.flatnonzero(got != expected)[:5]}"
    assert np.array_equal(keypoints["octave"], table[:, 5].astype(np.int32))
    assert ours.dtype == np.uint8 and descriptors.dtype == np.uint8
    assert ours.shape == descriptors.shape
    assert np.array_equal(ours, descriptors), f"rows differ: {np.flatnonzero((ours != descriptors).any(axis=1))[:5]}"


@pytest.mark.parametrize("flags,keywords", SETTINGS, ids=IDS)
def test_astronaut_equals_the_tool(cli, backend, tmp_path, flags, keywords):
    table, descriptors = run_extract(cli, ASTRONAUT, tmp_path / "astronaut", flags)
    extractor = clatch.Extractor(backend, **keywords)
    keypoints, ours = extractor.detect_and_describe(clatch.imread(ASTRONAUT))
    assert_same(table, descriptors, keypoints, ours)
    assert descriptors.shape[1] == extractor.config["bits"] // 8


@pytest.mark.parametrize("flags,keywords", SETTINGS[:3], ids=IDS[:3])
@pytest.mark.parametrize("seed", [1, 2])
def test_synthetic_gray_array_equals_the_tool(cli, backend, tmp_path, flags, keywords, seed):
    # The array goes in directly; the tool reads the same pixels from a PGM file.
    image = synthetic(300 + 17 * seed, 420 - 31 * seed, seed)
    table, descriptors = run_extract(cli, write_pnm(tmp_path / "img.pgm", image), tmp_path / "img", flags)
    keypoints, ours = clatch.Extractor(backend, **keywords).detect_and_describe(image)
    assert_same(table, descriptors, keypoints, ours)


def test_colour_array_equals_the_tool(cli, backend, tmp_path):
    # RGB: the package converts with the library's weights, the tool decodes the PPM and converts.
    image = synthetic(257, 311, 5, channels=3)
    table, descriptors = run_extract(cli, write_pnm(tmp_path / "rgb.ppm", image), tmp_path / "rgb", [])
    keypoints, ours = clatch.Extractor(backend).detect_and_describe(image)
    assert_same(table, descriptors, keypoints, ours)
    # The gray image the extractor saw is the tool's: the same file read back as gray.
    assert np.array_equal(clatch.to_gray(image), clatch.imread(tmp_path / "rgb.ppm"))


@pytest.mark.parametrize(
    "view",
    [
        lambda a: a[37:450, 21:400],  # a crop: rows apart by the full width, read in place
        lambda a: a[::2, :],  # every other row: a larger row step, read in place
        lambda a: a[:, ::-1],  # mirrored columns: copied
        lambda a: np.asfortranarray(a[5:300, 7:480]),  # column-major: copied
    ],
    ids=["crop", "row-step", "mirrored", "fortran"],
)
def test_strided_views_equal_the_tool(cli, backend, tmp_path, view):
    photo = clatch.imread(ASTRONAUT)
    image = view(photo)
    assert not image.flags.c_contiguous
    table, descriptors = run_extract(cli, write_pnm(tmp_path / "view.pgm", image), tmp_path / "view", [])
    keypoints, ours = clatch.Extractor(backend).detect_and_describe(image)
    assert_same(table, descriptors, keypoints, ours)


def test_detect_gives_the_tools_keypoints(cli, backend, tmp_path):
    table, _ = run_extract(cli, ASTRONAUT, tmp_path / "a", ["--single-scale"])
    keypoints = clatch.Extractor(backend, single_scale=True).detect(clatch.imread(ASTRONAUT))
    assert len(keypoints) == len(table)
    assert np.array_equal(keypoints["x"], table[:, 0].astype(np.float32))
    assert np.array_equal(keypoints["angle"], table[:, 3].astype(np.float32))
