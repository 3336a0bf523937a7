# Every ```python block of docs/python.md and README.md runs as written, from the repository's
# root (where their relative data/ paths point), each in a fresh namespace: a snippet that rots
# (a missing import, a renamed function) fails here. A block that is a copy of a file of
# docs/examples runs as that file, in a temporary directory (test_example.py); the copy is
# checked to be verbatim here.
import os
import re

import pytest

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
PAGES = ["docs/python.md", "README.md"]
EXAMPLES = os.path.join(ROOT, "docs", "examples")


def snippets(page):
    with open(os.path.join(ROOT, page)) as f:
        text = f.read()
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def example_sources():
    sources = []
    for name in sorted(os.listdir(EXAMPLES)):
        if name.endswith(".py"):
            with open(os.path.join(EXAMPLES, name)) as f:
                sources.append(f.read())
    return sources


def test_the_range_example_is_in_the_docs_verbatim():
    with open(os.path.join(EXAMPLES, "range_2d.py")) as f:
        assert f.read() in snippets("docs/python.md")


def test_the_pages_have_snippets():
    for page in PAGES:
        assert snippets(page), page


@pytest.mark.parametrize("page,index,code", [
    (page, k, code) for page in PAGES for k, code in enumerate(snippets(page))])
def test_snippet_runs(page, index, code, monkeypatch):
    if code in example_sources():
        pytest.skip("a copy of a docs/examples file, run as that file by test_example.py")
    monkeypatch.chdir(ROOT)
    exec(compile(code, f"{page} python block {index + 1}", "exec"), {"__name__": "__snippet__"})
