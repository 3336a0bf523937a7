# Every ```python block of docs/python.md and README.md runs as written, from the repository's
# root (where their relative data/ paths point), each in a fresh namespace: a snippet that rots
# (a missing import, a renamed function) fails here.
import os
import re

import pytest

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
PAGES = ["docs/python.md", "README.md"]


def snippets(page):
    with open(os.path.join(ROOT, page)) as f:
        text = f.read()
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_the_pages_have_snippets():
    for page in PAGES:
        assert snippets(page), page


@pytest.mark.parametrize("page,index,code", [
    (page, k, code) for page in PAGES for k, code in enumerate(snippets(page))])
def test_snippet_runs(page, index, code, monkeypatch):
    monkeypatch.chdir(ROOT)
    exec(compile(code, f"{page} python block {index + 1}", "exec"), {"__name__": "__snippet__"})
