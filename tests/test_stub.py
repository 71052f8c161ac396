"""The .pyi stub of the native module matches the compiled module."""

from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

import depthpose
import numpy as np
import pytest
from depthpose import _core


def stub_names() -> set[str]:
    stub = Path(depthpose.__file__).with_name("_core.pyi")
    tree = ast.parse(stub.read_text())
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names


def test_stub_matches_native_module():
    native = {n for n in dir(_core) if not n.startswith("__") or n == "__version__"}
    native.discard("__builtins__")
    stub = stub_names()
    assert native - stub == set(), f"missing from _core.pyi: {sorted(native - stub)}"
    assert stub - native == set(), f"in _core.pyi but not native: {sorted(stub - native)}"


def test_public_api_is_exported():
    for name in depthpose.__all__:
        assert hasattr(depthpose, name), name
    assert issubclass(depthpose.DepthPoseError, ValueError)
    assert (Path(depthpose.__file__).parent / "py.typed").exists()


def _signature_defaults(f):
    """The keyword arguments of ``f`` that have a default, at the default its runtime
    signature shows."""
    params = inspect.signature(f).parameters.values()
    return {p.name: p.default for p in params if p.default is not inspect.Parameter.empty}


def test_runtime_signatures_show_the_defaults_the_native_code_uses():
    assert _core.FitConfig(**_signature_defaults(_core.FitConfig)) == _core.FitConfig()
    settings = _core.TemplateDatabase._settings_hash
    assert settings(**_signature_defaults(settings)) == settings()
    camera = _core.Camera.kinect_v1_qvga()
    pose = _core.BodyModel.neutral_pose()
    pose[2] = 3.0
    depth, _ = _core.BodyModel().render_depth(pose, camera)
    for f, args in [
        (_core.foreground_mask, (depth,)),
        (_core.surface_normals, (depth, camera)),
        (_core.surface_context, (depth, camera)),
    ]:
        defaults = {k: v for k, v in _signature_defaults(f).items() if k != "mask"}
        given, default = f(*args, **defaults), f(*args)
        if not isinstance(given, tuple):
            given, default = (given,), (default,)
        for a, b in zip(given, default, strict=True):
            np.testing.assert_array_equal(a, b)
    for f in (_core.fit_pose, _core.fit_poses, _core.BodyModel.fit_shape):
        assert Ellipsis not in _signature_defaults(f).values(), f


def test_grouped_keywords_refuse_unknown_names_as_python_does():
    depth = np.full((24, 32), 2.0, np.float32)
    camera = _core.Camera(30.0, 30.0, 15.5, 11.5, 32, 24)
    pose = _core.BodyModel.neutral_pose()
    calls = [
        (lambda: _core.FitConfig(sigmaa=1.0), "FitConfig.__new__()", "sigmaa"),
        (lambda: _core.fit_pose(depth, camera, pose, maks=None), "fit_pose()", "maks"),
        (lambda: _core.foreground_mask(depth, min_dept=0.1), "foreground_mask()", "min_dept"),
        (
            lambda: _core.TemplateDatabase.from_depths(depth, renderer="ellipsoid"),
            "TemplateDatabase.from_depths()",
            "renderer",
        ),
    ]
    for call, function, name in calls:
        with pytest.raises(TypeError, match=re.escape(f"{function} got an unexpected keyword")):
            call()
        with pytest.raises(TypeError, match=f"'{name}'"):
            call()
    with pytest.raises(TypeError):
        _core.FitConfig(1.0)  # keyword-only
