"""The Python examples in the user guide pages run as written.

Each page's ```python blocks run in order in one namespace, in a temporary folder. Blocks that start
with ``# needs the measured data`` are skipped when the data folder is absent (the rest of the page
still runs). Every page with a Python example is run by some test: here by default (pages that take
seconds), here under ``-m slow`` (pages that take minutes), or by the test named in
``RUN_ELSEWHERE``, which also checks what the page's numbers say.
"""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = ["docs/getting-started.md", "docs/concepts.md", "README.md", "docs/architecture.md",
         "docs/codegen.md", "docs/estimators.md", "docs/identification.md", "docs/mhe.md",
         "docs/models.md"]
SLOW_PAGES = ["docs/autopilots.md"]          # its MPC-against-PID table is measured by one of its blocks
RUN_ELSEWHERE = {
    "docs/data.md": "tests/test_nmea.py",
    "docs/trial-design.md": "tests/test_design_study.py",      # with the fit file its second block reads
    "docs/tutorial-filter-guidelines.md": "tests/test_tutorials.py",
    "docs/tutorial-fossen2021.md": "tests/test_tutorials.py",
    "docs/tutorial-shi2009.md": "tests/test_tutorials.py",
    "docs/tutorial-tomera2011.md": "tests/test_tutorials.py",
    "docs/tutorial-kvlcc2-marin.md": "tests/test_studies_kvlcc2_marin.py",
}


@pytest.mark.parametrize("page", PAGES)
def test_python_blocks_run(page, tmp_path, monkeypatch):
    _run_page(page, tmp_path, monkeypatch)


@pytest.mark.slow
@pytest.mark.parametrize("page", SLOW_PAGES)
def test_python_blocks_of_slow_pages_run(page, tmp_path, monkeypatch):
    _run_page(page, tmp_path, monkeypatch)


def test_every_page_with_python_examples_is_run():
    with_python = {str(p.relative_to(ROOT)) for p in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
                   if "```python" in p.read_text()}
    listed = [*PAGES, *SLOW_PAGES, *RUN_ELSEWHERE]
    assert len(listed) == len(set(listed)), "a page is listed twice"
    assert with_python == set(listed), (f"not run by any test: {sorted(with_python - set(listed))}; "
                                        f"listed without a Python example: {sorted(set(listed) - with_python)}")
    for page, test in RUN_ELSEWHERE.items():
        assert Path(page).name in (ROOT / test).read_text(), f"{test} does not run {page}"


def _run_page(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / page).read_text(), re.S)
    assert blocks, f"{page} has no Python example"
    namespace: dict = {}
    skipped = 0
    for block in blocks:
        if block.startswith("# needs the measured data") and _no_data():
            skipped += 1                  # the rest of the page still runs
            continue
        exec(compile(block, f"{page}", "exec"), namespace)
    if skipped:
        pytest.skip(f"{page}: {skipped} block(s) need the measured data, which are absent (the others ran)")


def _no_data() -> bool:
    from casship.io import data_dir

    try:
        return data_dir() is None
    except FileNotFoundError:
        return True
