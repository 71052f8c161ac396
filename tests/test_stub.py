"""The .pyi stub of the native module matches the compiled module."""

from __future__ import annotations

import ast
from pathlib import Path

import depthpose
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
