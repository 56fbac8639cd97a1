"""The type stubs name what the module has: every public name and method of the module is in
__init__.pyi, and the stub declares nothing the module lacks."""

import ast
import os

import densemap

STUB = os.path.join(os.path.dirname(densemap.__file__), "__init__.pyi")


def stub_names():
    tree = ast.parse(open(STUB).read())
    names = {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            names[node.name] = {n.name for n in node.body
                                if isinstance(n, (ast.FunctionDef, ast.AnnAssign))
                                and not getattr(n, "name", "").startswith("__")}
        elif isinstance(node, ast.FunctionDef):
            names[node.name] = None
        elif isinstance(node, ast.AnnAssign):
            names[node.target.id] = None
    return names


def test_stubs_match_the_module():
    stubs = stub_names()
    for name in densemap.__all__:
        assert name in stubs, f"{name} is missing from __init__.pyi"
        obj = getattr(densemap, name)
        if isinstance(obj, type) and not issubclass(obj, Exception):
            public = {m for m in dir(obj) if not m.startswith("_")}
            assert public == stubs[name], f"{name}: module {sorted(public)} stub {sorted(stubs[name])}"
    for name in stubs:
        assert hasattr(densemap, name) or name in ("ArrayLike", "Point", "Box", "PathLike"), name


def test_everything_public_has_a_docstring():
    for name in densemap.__all__:
        obj = getattr(densemap, name)
        if callable(obj):
            assert obj.__doc__, f"densemap.{name} has no docstring"
        if isinstance(obj, type) and not issubclass(obj, Exception):
            for member in dir(obj):
                if member.startswith("_"):
                    continue
                assert getattr(obj, member).__doc__, f"densemap.{name}.{member} has no docstring"
