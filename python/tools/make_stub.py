"""Writes the type stub of the extension module secure._secure from the built module itself.

    PYTHONPATH=build/python /usr/bin/python3 python/tools/make_stub.py          # rewrite the stub
    PYTHONPATH=build/python /usr/bin/python3 python/tools/make_stub.py --check  # exit 1 if stale

The stub (python/secure/_secure.pyi) is kept in the repository, so an IDE or a type checker
has it without a build; python/tests/test_stub.py (ctest -L python) fails when it no longer
matches the module. Everything in it comes from pybind11's signatures and docstrings (the
binding's py::arg names and types, python/src/common.h's Typed names): to change the stub,
change the binding, rebuild and run this script. pybind11-stubgen is not packaged by Debian;
this is the part of it the module needs (no overloads, no enums, no nested classes).

An argument or result typed `handle` or `object` (a py::handle / py::object in the binding) is
an error: give it a Typed name in python/src/common.h.
"""
import argparse
import ast
import difflib
import importlib
import inspect
import os
import re
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
STUB = os.path.join(os.path.dirname(HERE), "secure", "_secure.pyi")
MODULE = "secure._secure"

HEADER = '''\
# The type stub of secure._secure (the C++ extension; the package `secure` re-exports it).
# Generated from the built module by python/tools/make_stub.py: do not edit by hand. Change
# the binding (python/src/), rebuild, then run
#   PYTHONPATH=build/python /usr/bin/python3 python/tools/make_stub.py
# python/tests/test_stub.py checks that this file matches the module.
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy
from numpy.typing import ArrayLike, NDArray
'''

# pybind11's spelling -> the stub's.
_REPLACEMENTS = [
    (re.compile(r"\bsecure\._secure\."), ""),
    (re.compile(r"\bnumpy\.ndarray\[(numpy\.\w+)\]"), r"NDArray[\1]"),
    (re.compile(r"\bnumpy\.typing\.NDArray\b"), "NDArray"),
    (re.compile(r"\bnumpy\.typing\.ArrayLike\b"), "ArrayLike"),
]
_UNTYPED = re.compile(r"\b(handle|object)\b")
_CPP_NAME = re.compile(r"::")


class StubError(Exception):
    pass


def _type(text, where):
    for pattern, repl in _REPLACEMENTS:
        text = pattern.sub(repl, text)
    if _UNTYPED.search(text) or _CPP_NAME.search(text):
        raise StubError(f"{where}: the type '{text}' names no Python type (a py::handle or "
                        "py::object, or a C++ class registered after its use): give it a Typed "
                        "name in python/src/common.h, or register the class first")
    return text


def _split_top(text, sep=","):
    """Splits at `sep` outside brackets and quotes."""
    parts, depth, quote, start = [], 0, None, 0
    for i, c in enumerate(text):
        if quote:
            if c == quote and text[i - 1] != "\\":
                quote = None
        elif c in "'\"":
            quote = c
        elif c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == sep and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return [p.strip() for p in parts if p.strip()]


def _default(text):
    """A literal default as written by pybind11 (its repr), else `...`."""
    try:
        ast.literal_eval(text)
        return text
    except (ValueError, SyntaxError):
        return "..."


def _parse_signature(doc, name, where):
    """pybind11's first docstring line 'name(a: T, b: U = d, *, **kwargs) -> R' and the rest."""
    if not doc:
        raise StubError(f"{where}: no docstring (not a pybind11 function?)")
    first, _, rest = doc.partition("\n")
    if "Overloaded function." in rest:
        raise StubError(f"{where}: overloaded functions are not supported by this generator")
    m = re.match(r"^\s*" + re.escape(name) + r"\((.*)\)\s*->\s*(.+)$", first)
    if not m:
        raise StubError(f"{where}: cannot read the signature line {first!r}")
    params = []
    for p in _split_top(m.group(1)):
        if p in ("*", "/"):
            params.append(p)
            continue
        if p.startswith("**"):
            params.append(f"{p}: Any")
            continue
        if p.startswith("*"):
            params.append(f"{p}: Any")
            continue
        head, eq, default = p.partition("=")
        pname, colon, ptype = head.partition(":")
        pname = pname.strip()
        if not colon:
            raise StubError(f"{where}: parameter {p!r} has no type")
        if pname == "arg0" and not params and where.count(".") >= 1:
            pname = "self"
        if pname == "self":
            params.append("self")
            continue
        if re.fullmatch(r"arg\d+", pname):
            raise StubError(f"{where}: parameter {pname} has no name: add py::arg(\"...\")")
        ptype = _type(ptype.strip(), f"{where}({pname})")
        if eq:
            d = _default(default.strip())
            if d == "None" and not (ptype.startswith("Optional[") or ptype == "Any"):
                ptype = f"Optional[{ptype}]"
            params.append(f"{pname}: {ptype} = {d}")
        else:
            params.append(f"{pname}: {ptype}")
    result = _type(m.group(2).strip(), f"{where} -> result")
    return params, result, rest.strip("\n")


def _docstring(text, indent):
    text = inspect.cleandoc(text) if text else ""
    if not text:
        return []
    text = text.replace("\\", "\\\\").replace('"""', '\\"\\"\\"')
    lines = text.split("\n")
    if len(lines) == 1:
        return [f'{indent}"""{lines[0]}"""']
    return [f'{indent}"""{lines[0]}'] + [(indent + l) if l else "" for l in lines[1:]] + [
        f'{indent}"""']


def _function(name, func, where, indent, decorator=None):
    params, result, doc = _parse_signature(func.__doc__, name, where)
    out = [f"{indent}@{decorator}"] if decorator else []
    body = _docstring(doc, indent + "    ")
    sig = f"{indent}def {name}({', '.join(params)}) -> {result}:"
    if body:
        return out + [sig] + body + [f"{indent}    ..."]
    return out + [sig + " ..."]


def _property(name, prop, where, indent):
    params, result, doc = _parse_signature(prop.fget.__doc__, "", where)
    lines = [f"{indent}@property", f"{indent}def {name}(self) -> {result}:"]
    body = _docstring(prop.__doc__ if prop.__doc__ != prop.fget.__doc__ else doc, indent + "    ")
    if body:
        return lines + body + [f"{indent}    ..."]
    lines[-1] += " ..."
    return lines


def _is_pybind_function(obj):
    return type(obj).__name__ in ("builtin_function_or_method", "instancemethod")


def _class(name, cls):
    lines = [f"class {name}:"]
    lines += _docstring(cls.__doc__, "    ")
    for key, value in vars(cls).items():
        where = f"{name}.{key}"
        if key in ("__doc__", "__module__", "__dict__", "__weakref__"):
            continue
        if isinstance(value, property):
            lines += _property(key, value, where, "    ")
        elif isinstance(value, staticmethod):
            lines += _function(key, value.__func__, where, "    ", decorator="staticmethod")
        elif _is_pybind_function(value):
            func = getattr(value, "__func__", value)
            lines += _function(key, func, where, "    ")
        elif key == "__init__":
            continue  # pybind11's default: "No constructor defined", so none in the stub
        else:
            raise StubError(f"{where}: an attribute of type {type(value).__name__} the generator "
                            "does not know")
    return lines


def generate(module=None):
    """The stub's text for the imported module (default: secure._secure)."""
    module = module or importlib.import_module(MODULE)
    lines = [HEADER]
    doc = _docstring(module.__doc__, "")
    if doc:
        lines[0:0] = doc + [""]
    body = []
    for name, value in vars(module).items():
        if name.startswith("__") and name != "__version__":
            continue
        if name == "__version__":
            body.append(["__version__: str"])
        elif inspect.isclass(value):
            body.append(_class(name, value))
        elif _is_pybind_function(value):
            body.append(_function(name, value, name, ""))
        else:
            raise StubError(f"{name}: a module attribute of type {type(value).__name__} the "
                            "generator does not know")
    text = "\n".join(lines) + "\n" + "\n\n".join("\n".join(b) for b in body) + "\n"
    ast.parse(text)  # a syntax error here is a generator bug
    return text


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="compare with the stub in the repository; exit 1 if it differs")
    parser.add_argument("--out", default=STUB, help="the stub to write or check (%(default)s)")
    args = parser.parse_args(argv)
    try:
        text = generate()
    except StubError as e:
        print(f"make_stub.py: {e}", file=sys.stderr)
        return 1
    if args.check:
        with open(args.out) as f:
            current = f.read()
        if current != text:
            sys.stdout.writelines(difflib.unified_diff(
                current.splitlines(True), text.splitlines(True), args.out, "the built module"))
            print(f"make_stub.py: {args.out} is stale: run python/tools/make_stub.py",
                  file=sys.stderr)
            return 1
        return 0
    with open(args.out, "w") as f:
        f.write(text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
