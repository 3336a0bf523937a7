# The type stub (python/arbor_slam.pyi, found beside the module) cannot drift from the module: the
# same public names, classes with the same public members, functions and methods with the same
# parameters as pybind11's signatures; every public name has a docstring; and mypy passes on the
# stub (--strict) and on the documented examples (docs/examples, the pages' python blocks).
import ast
import os
import re
import subprocess
import sys

import pytest

import arbor_slam
from test_docs_snippets import PAGES, ROOT, snippets

STUB = os.path.join(os.path.dirname(arbor_slam.__file__), arbor_slam.__name__ + ".pyi")
EXAMPLES = os.path.join(ROOT, "docs", "examples")
SIGNATURE = re.compile(r"^(?:\d+\. )?(\w+)\((.*)\)(?: -> .*)?$")


def stub_tree():
    with open(STUB) as f:
        return ast.parse(f.read())


def public(name):
    return not name.startswith("_")


def stub_names(body):
    """Public top-level names of a stub body: classes, functions, annotated variables."""
    names = set()
    for node in body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return {n for n in names if public(n)}


def stub_parameters(function):
    """The parameter names of a stub function, without self; **kwargs as '**'."""
    a = function.args
    names = [p.arg for p in a.posonlyargs + a.args + a.kwonlyargs]
    names += ["**"] if a.kwarg else []
    return names[1:] if names[:1] == ["self"] else names


def split_top_level(text):
    """Splits at commas outside brackets (types like numpy.ndarray[numpy.float64[m, n]])."""
    parts, depth, current = [], 0, ""
    for ch in text:
        if ch in "[(":
            depth += 1
        elif ch in "])":
            depth -= 1
        if ch == "," and depth == 0:
            parts.append(current)
            current = ""
        else:
            current += ch
    return [p.strip() for p in parts + [current] if p.strip()]


def runtime_parameters(obj):
    """Each pybind11 overload's parameter names, from its docstring signatures (numbered when
    overloaded, after a generic `name(*args, **kwargs)`)."""
    doc = obj.__doc__ or ""
    overloaded = "Overloaded function." in doc
    overloads = []
    for line in doc.splitlines():
        if overloaded and not line[:1].isdigit():
            continue
        match = SIGNATURE.match(line.strip())
        if match and match.group(1) == obj.__name__:
            names = [p.split(":")[0].split("=")[0].strip() for p in split_top_level(match.group(2))]
            names = ["**" if n.startswith("**") else n for n in names]
            overloads.append(names[1:] if names[:1] == ["self"] else names)
    return overloads


def documented(doc):
    """The docstring without pybind11's signature lines is not empty."""
    lines = [line.strip() for line in (doc or "").splitlines()]
    return any(line and not SIGNATURE.match(line) and line != "Overloaded function."
               for line in lines)


def test_the_stub_is_beside_the_module():
    assert os.path.isfile(STUB), STUB
    with open(STUB) as f, open(os.path.join(ROOT, "python", "arbor_slam.pyi")) as source:
        assert f.read() == source.read()


def test_the_stub_has_the_modules_public_names():
    module = {n for n in dir(arbor_slam) if public(n)}
    assert stub_names(stub_tree().body) == module


def test_the_stubs_classes_have_the_modules_members():
    for node in stub_tree().body:
        if isinstance(node, ast.ClassDef):
            runtime = {n for n in vars(getattr(arbor_slam, node.name)) if public(n)}
            assert stub_names(node.body) == runtime, node.name


def test_the_stubs_parameters_are_the_modules():
    checked = 0
    scopes = [(arbor_slam, stub_tree().body)] + [
        (getattr(arbor_slam, c.name), c.body) for c in stub_tree().body if isinstance(c, ast.ClassDef)]
    for owner, body in scopes:
        defined = {}
        for node in body:
            if not isinstance(node, ast.FunctionDef):
                continue
            operator = node.name.startswith("__") and node.name != "__init__"  # positional
            if not operator and not any(
                    isinstance(d, ast.Name) and d.id == "property" for d in node.decorator_list):
                defined.setdefault(node.name, []).append(stub_parameters(node))
        for name, stubbed in defined.items():
            runtime = runtime_parameters(getattr(owner, name))
            if runtime:  # a builtin slot (e.g. __copy__ without a signature line) is skipped
                assert sorted(stubbed) == sorted(runtime), f"{owner.__name__}.{name}"
                checked += 1
    assert checked > 100


def test_every_public_name_has_a_docstring():
    missing = []
    for name in (n for n in dir(arbor_slam) if public(n) and n != "__version__"):
        obj = getattr(arbor_slam, name)
        if not documented(obj.__doc__):
            missing.append(name)
        if isinstance(obj, type):
            missing += [f"{name}.{member}" for member, value in vars(obj).items()
                        if public(member) and not documented(getattr(value, "__doc__", None))]
    assert not missing


def run_mypy(tmp_path, *args):
    env = dict(os.environ, MYPYPATH=os.path.dirname(STUB))
    out = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", os.path.join(ROOT, "tests", "python",
                                                                     "mypy.ini"),
         "--cache-dir", str(tmp_path / "cache"), *args],
        capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stdout + out.stderr


@pytest.fixture(scope="module")
def mypy_dir(tmp_path_factory):
    pytest.importorskip("mypy", reason="mypy (python3-mypy) is not installed")
    return tmp_path_factory.mktemp("mypy")


def test_mypy_passes_on_the_stub(mypy_dir):
    run_mypy(mypy_dir, "--strict", "-m", arbor_slam.__name__)


def test_mypy_passes_on_the_examples(mypy_dir):
    files = [os.path.join(EXAMPLES, f) for f in sorted(os.listdir(EXAMPLES)) if f.endswith(".py")]
    for page in PAGES:
        for k, code in enumerate(snippets(page)):
            path = mypy_dir / f"{os.path.basename(page).replace('.', '_')}_block_{k + 1}.py"
            path.write_text(code)
            files.append(str(path))
    run_mypy(mypy_dir, *files)
