"""The package's surface: exports, stubs and docstrings, dtypes, configuration, zero-copy."""

from __future__ import annotations

import ast
import inspect
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import clatch
from clatch import _clatch
from helpers import ASTRONAUT, synthetic

STUB = Path(_clatch.__file__).with_name("_clatch.pyi")
PUBLIC_CLASSES = [clatch.Extractor, clatch.Matcher, clatch.OpencvLatch, clatch.colmap.ImageFolder]
# Made by the package only (no constructor): documented and in the stub all the same.
MADE_CLASSES = [clatch.colmap.PinholeCamera, clatch.TwoViewGeometry]


def stub_tree() -> ast.Module:
    assert STUB.is_file(), f"{STUB} is installed next to the native module"
    return ast.parse(STUB.read_text())


def test_every_export_exists_and_is_documented():
    for name in clatch.__all__:
        obj = getattr(clatch, name)
        if inspect.isclass(obj) or inspect.isroutine(obj):
            assert obj.__doc__ and obj.__doc__.strip(), f"{name} has no docstring"
    assert (Path(clatch.__file__).parent / "py.typed").is_file()


def test_every_method_is_documented():
    for cls in PUBLIC_CLASSES + MADE_CLASSES:
        for name, member in vars(cls).items():
            if name.startswith("_"):
                continue
            assert member.__doc__ and member.__doc__.strip(), f"{cls.__name__}.{name} has no docstring"


def test_the_stub_lists_what_the_module_has():
    tree = stub_tree()
    names = set()
    classes = {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            names.add(node.name)
            classes[node.name] = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
        elif isinstance(node, ast.FunctionDef):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    assert set(_clatch.__all__) <= names, f"missing from the stub: {set(_clatch.__all__) - names}"
    for cls in PUBLIC_CLASSES + MADE_CLASSES:
        runtime = {n for n in vars(cls) if not n.startswith("_")}
        assert runtime == {n for n in classes[cls.__name__] if not n.startswith("_")}, cls.__name__
    python_side = set(clatch._exceptions.__all__) | set(clatch._interop.__all__)
    assert set(clatch.__all__) <= names | python_side


def test_signatures_follow_the_stub():
    if sys.version_info < (3, 10):
        pytest.skip("classes of an abi3 module carry no text signature before Python 3.10")
    tree = stub_tree()
    stub_new = {
        node.name: next(n for n in node.body if isinstance(n, ast.FunctionDef) and n.name == "__new__")
        for node in tree.body
        if isinstance(node, ast.ClassDef) and any(isinstance(n, ast.FunctionDef) and n.name == "__new__" for n in node.body)
    }
    for cls in PUBLIC_CLASSES:
        runtime = inspect.signature(cls)
        stub = stub_new[cls.__name__].args
        stub_names = [a.arg for a in stub.args[1:]] + [a.arg for a in stub.kwonlyargs]
        assert list(runtime.parameters) == stub_names, cls.__name__
        stub_defaults = [ast.literal_eval(d) for d in stub.defaults] + [ast.literal_eval(d) for d in stub.kw_defaults]
        runtime_defaults = [p.default for p in runtime.parameters.values() if p.default is not inspect.Parameter.empty]
        assert runtime_defaults == stub_defaults, cls.__name__


def test_the_stub_passes_stubtest(tmp_path):
    # mypy's stubtest imports the module and checks every name, signature and default against the
    # stub (CI installs mypy; elsewhere this is skipped without it).
    pytest.importorskip("mypy.stubtest")
    config = tmp_path / "mypy.ini"
    config.write_text("[mypy]\n")  # none of a surrounding project's settings
    run = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "clatch._clatch", "--mypy-config-file", str(config)],
        cwd=tmp_path,
        env={**os.environ, "MYPY_CACHE_DIR": str(tmp_path / "cache")},
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stdout + run.stderr


def test_the_package_passes_mypy_strict(tmp_path):
    # The package's Python files against the stub, as a user's type checker sees them.
    pytest.importorskip("mypy.api")
    config = tmp_path / "mypy.ini"
    config.write_text("[mypy]\n")
    run = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", "--config-file", str(config), str(Path(clatch.__file__).parent)],
        cwd=tmp_path,
        env={**os.environ, "MYPY_CACHE_DIR": str(tmp_path / "cache")},
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stdout + run.stderr


def test_dtypes_mirror_the_library_types():
    assert clatch.KEYPOINT_DTYPE.names == ("x", "y", "size", "angle", "response", "octave")
    assert [clatch.KEYPOINT_DTYPE[n] for n in clatch.KEYPOINT_DTYPE.names] == [np.dtype(np.float32)] * 5 + [np.dtype(np.int32)]
    assert clatch.KEYPOINT_DTYPE.itemsize == 24
    assert clatch.MATCH_DTYPE.names == ("query", "train", "distance")
    assert all(clatch.MATCH_DTYPE[n] == np.uint32 for n in clatch.MATCH_DTYPE.names)


def test_defaults_are_the_librarys():
    default, fast = clatch.Extractor().config, clatch.Extractor(single_scale=True).config
    # The two presets differ exactly where ExtractorConfig::single_scale() says they do.
    differ = {k for k in default if default[k] != fast[k]}
    assert differ == {"keypoint_size", "level_budget", "subpixel", "pyramid"}
    assert fast["pyramid"] is False and default["pyramid"] == (8, 1.2)
    assert len(default["weights"]) == 64
    # Every setting reads back, and an extractor built from them is equal.
    for config in (default, fast, {**default, "grid": 4, "bits": 96, "pyramid": (3, 2.0)}):
        assert clatch.Extractor(**config).config == config
    m = clatch.Matcher()
    assert (m.ratio, m.cross_check, m.max_distance, m.backend) == (0.8, True, None, "cpu")
    assert clatch.Matcher(ratio=None, max_distance=40).max_distance == 40
    assert "Extractor(" in repr(clatch.Extractor()) and "Matcher(" in repr(m)


def test_settings_change_the_result(backend):
    photo = clatch.imread(ASTRONAUT)
    base_k, _ = clatch.Extractor(backend).detect_and_describe(photo)
    for keywords in ({"threshold": 40}, {"max_keypoints": 300}, {"grid": 8}, {"single_scale": True}):
        k, d = clatch.Extractor(backend, **keywords).detect_and_describe(photo)
        assert len(k) == len(d) > 0
        assert len(k) != len(base_k) or not np.array_equal(k, base_k), keywords
    k, _ = clatch.Extractor(backend, max_keypoints=300).detect_and_describe(photo)
    assert len(k) == 300


def test_zero_copy_where_the_layout_allows():
    photo = clatch.imread(ASTRONAUT)
    assert _clatch._reads_in_place(photo)
    assert _clatch._reads_in_place(photo[10:300, 20:400])  # rows apart by the full width
    assert _clatch._reads_in_place(photo[::3])
    assert not _clatch._reads_in_place(photo.T)
    assert not _clatch._reads_in_place(photo[:, ::2])
    assert not _clatch._reads_in_place(np.stack([photo] * 3, axis=-1))  # colour is converted
    keypoints, descriptors = clatch.Extractor(max_keypoints=200).detect_and_describe(photo)
    # Results are the library's own buffers, handed over rather than copied.
    for array in (keypoints, descriptors):
        assert not array.flags.owndata and array.base is not None
        assert array.flags.c_contiguous and array.flags.writeable


def test_to_gray_uses_the_tools_weights():
    rgb = synthetic(70, 90, 3, channels=3)
    r, g, b = (rgb[..., c].astype(np.int64) for c in range(3))
    expected = ((4899 * r + 9617 * g + 1868 * b + 8192) >> 14).astype(np.uint8)
    assert np.array_equal(clatch.to_gray(rgb), expected)
    rgba = np.concatenate([rgb, np.full((70, 90, 1), 7, np.uint8)], axis=-1)
    assert np.array_equal(clatch.to_gray(rgba), expected)
    assert np.array_equal(clatch.to_gray(rgb[::-1, ::2]), expected[::-1, ::2])
    gray = rgb[..., 0]
    assert np.array_equal(clatch.to_gray(gray), gray)


def test_describe_gives_detect_and_describe_on_one_level(backend):
    photo = clatch.imread(ASTRONAUT)
    extractor = clatch.Extractor(backend, single_scale=True, max_keypoints=500)
    keypoints, descriptors = extractor.detect_and_describe(photo)
    extra = np.zeros(2, dtype=clatch.KEYPOINT_DTYPE)
    extra["x"], extra["y"], extra["size"] = [3.0, 250.0], [3.0, 260.0], 64.0
    given = np.concatenate([keypoints[:100], extra])
    described, rows, index = extractor.describe(photo, given)
    assert index.tolist() == list(range(100)) + [101]  # keypoint 100's window leaves the image
    assert np.array_equal(described, given[index])
    assert np.array_equal(rows[:100], descriptors[:100])


def test_imread_gives_the_files_gray_pixels():
    photo = clatch.imread(ASTRONAUT)
    assert photo.dtype == np.uint8 and photo.ndim == 2 and photo.flags.c_contiguous
    header = ASTRONAUT.read_bytes()[:26]  # PNG signature, IHDR: width, height, depth, colour type
    width, height = int.from_bytes(header[16:20], "big"), int.from_bytes(header[20:24], "big")
    assert photo.shape == (height, width)
    assert header[25] == 0, "a gray PNG: its pixels come back unchanged, so they vary"
    assert photo.std() > 10
