"""The type stub secure/_secure.pyi matches the built module (python/tools/make_stub.py writes
it from pybind11's signatures and docstrings), every argument and result has a Python type and
a name, the package is marked typed (PEP 561), and help() reads as the stub does."""
import ast
import os
import pydoc
import sys

import pytest

import secure
from secure import _secure

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "python", "tools"))
import make_stub  # noqa: E402

STUB = os.path.join(ROOT, "python", "secure", "_secure.pyi")


def test_stub_matches_the_module():
    with open(STUB) as f:
        current = f.read()
    generated = make_stub.generate(_secure)
    if current != generated:
        import difflib
        diff = "".join(difflib.unified_diff(current.splitlines(True), generated.splitlines(True),
                                            "python/secure/_secure.pyi", "the built module"))
        pytest.fail("the stub is stale: run PYTHONPATH=build/python /usr/bin/python3 "
                    "python/tools/make_stub.py\n" + diff)


def test_stub_declares_every_public_name_the_package_exports():
    tree = ast.parse(open(STUB).read())
    declared = {n.name for n in tree.body if isinstance(n, (ast.ClassDef, ast.FunctionDef))}
    declared |= {n.target.id for n in tree.body if isinstance(n, ast.AnnAssign)}
    public = {n for n in dir(_secure) if not n.startswith("_")}
    assert public <= declared
    # The package offers every public name of the extension (itself, or a Python wrapper of it).
    assert all(hasattr(secure, n) for n in public), sorted(n for n in public if not hasattr(secure, n))
    assert set(secure.__all__) >= public, sorted(public - set(secure.__all__))
    assert "__version__" in declared


def test_the_package_is_typed_and_ships_the_stub():
    package = os.path.dirname(secure.__file__)
    assert os.path.isfile(os.path.join(package, "py.typed"))
    with open(os.path.join(package, "_secure.pyi")) as f, open(STUB) as g:
        assert f.read() == g.read()


def test_the_generator_refuses_untyped_and_unnamed_arguments():
    with pytest.raises(make_stub.StubError, match="names no Python type"):
        make_stub._parse_signature("f(x: handle) -> None", "f", "f")
    with pytest.raises(make_stub.StubError, match="names no Python type"):
        make_stub._parse_signature("f(x: int) -> object", "f", "f")
    with pytest.raises(make_stub.StubError, match="names no Python type"):
        make_stub._parse_signature("f(x: secure::python::AirlReward = None) -> None", "f", "f")
    with pytest.raises(make_stub.StubError, match="has no name"):
        make_stub._parse_signature("f(arg0: int) -> None", "f", "f")
    params, result, _ = make_stub._parse_signature(
        "f(a: numpy.ndarray[numpy.float32], b: secure._secure.Policy = None, *, "
        "c: Dict[str, int] = {'x': 1}, **kwargs) -> Tuple[int, str]\n\nDoc.", "f", "f")
    assert params == ["a: NDArray[numpy.float32]", "b: Optional[Policy] = None", "*",
                      "c: Dict[str, int] = {'x': 1}", "**kwargs: Any"]
    assert result == "Tuple[int, str]"


def test_help_names_the_arguments_and_their_types():
    text = pydoc.render_doc(secure.Shield, renderer=pydoc.plaintext)
    assert "decide(self: secure._secure.Shield, state: numpy.typing.ArrayLike, " \
           "mu: numpy.typing.ArrayLike, sigma: numpy.typing.ArrayLike)" in text
    assert "handle" not in text
    text = pydoc.render_doc(secure.train_barrier, renderer=pydoc.plaintext)
    assert "train_barrier(safe: numpy.typing.ArrayLike, near_dangerous: numpy.typing.ArrayLike, " \
           "features: Optional[Sequence[str]] = None, **kwargs) -> Tuple[Barrier, " \
           "Dict[str, Any]]" in text
