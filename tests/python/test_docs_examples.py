"""The examples of README.md and docs/ run as written, and the repository paths they name exist.

Every fenced block of those pages is one of:
  ```python   run, in order, in one namespace per page, in a fresh folder;
  ```sh       run by bash (with build/apps on PATH) in the same folder, and must be marked
              runnable by an HTML comment `<!-- runnable -->` on the line before the fence;
  ```cpp      a complete C++ program, compiled against the public headers (syntax and types);
  ```text     output, commands with machine-specific arguments (benchmarks), or layouts: not run.
Any other language fails the test, so that no example escapes it.
"""
import os
import pathlib
import re
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
BUILD = ROOT / "build"
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
RUN_MARK = "<!-- runnable -->"
FENCE = re.compile(r"^(?P<indent> *)```(?P<lang>[^\n`]*)\n(?P<code>.*?)^(?P=indent)```[ \t]*$", re.M | re.S)
KNOWN = {"python", "sh", "cpp", "text", "{toctree}", "{doxygenfile}"}


def blocks(page):
    """[(language, code, marked runnable, line)] of a page's fenced blocks, in order."""
    text = page.read_text()
    out = []
    for m in FENCE.finditer(text):
        before = text[: m.start()].rstrip("\n").rsplit("\n", 1)[-1].strip()
        lang = m.group("lang").strip().split(" ")[0]
        out.append((lang, m.group("code"), before == RUN_MARK, text.count("\n", 0, m.start()) + 1))
    return out


def rel(page):
    return str(page.relative_to(ROOT))


@pytest.mark.parametrize("page", PAGES, ids=rel)
def test_every_block_is_of_a_known_kind(page):
    bad = [f"{rel(page)}:{line}: ```{lang}" for lang, _, marked, line in blocks(page) if lang not in KNOWN]
    bad += [f"{rel(page)}:{line}: a sh block not marked {RUN_MARK}"
            for lang, _, marked, line in blocks(page) if lang == "sh" and not marked]
    assert not bad, "blocks the tests would not run:\n" + "\n".join(bad)


RUNNABLE = [p for p in PAGES if any(lang in ("python", "sh") for lang, *_ in blocks(p))]


@pytest.mark.parametrize("page", RUNNABLE, ids=rel)
def test_examples_run(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    env = dict(os.environ)
    env["PATH"] = f"{BUILD / 'apps'}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = str(BUILD / "python")
    namespace = {"__name__": "__main__"}
    ran = 0
    for lang, code, marked, line in blocks(page):
        if lang == "python":
            exec(compile(code, f"{rel(page)}:{line}", "exec"), namespace)
            ran += 1
        elif lang == "sh" and marked:
            r = subprocess.run(["bash", "-euo", "pipefail", "-c", code], cwd=tmp_path, env=env,
                               capture_output=True, text=True, timeout=600)
            assert r.returncode == 0, f"{rel(page)}:{line} exited {r.returncode}:\n{r.stdout}\n{r.stderr}"
            ran += 1
    assert ran > 0


CPP = [(p, code, line) for p in PAGES for lang, code, _, line in blocks(p) if lang == "cpp"]


@pytest.mark.skipif(shutil.which("g++") is None, reason="no C++ compiler")
@pytest.mark.parametrize("page,code,line", CPP, ids=[f"{rel(p)}:{n}" for p, _, n in CPP])
def test_cpp_examples_compile(page, code, line, tmp_path):
    src = tmp_path / "example.cpp"
    src.write_text(code)
    cmd = ["g++", "-std=c++17", "-fsyntax-only", f"-I{ROOT / 'lib' / 'include'}", "-I/usr/include/eigen3", str(src)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, f"{rel(page)}:{line} does not compile:\n{r.stderr}"


# Repository paths a page names: words in backquotes or link targets that start with one of the
# tree's top-level folders or name a top-level file.
TOP = ("lib/", "apps/", "bindings/", "scripts/", "tests/", "docs/", "notebooks/", ".ci/")
TOP_FILES = {"README.md", "CHANGELOG.md", "LICENSE", "CMakeLists.txt"}


def named_paths(page):
    text = page.read_text()
    names = set(re.findall(r"`([^`\s]+)`", text)) | set(re.findall(r"\]\(([^)\s#]+)", text))
    out = set()
    for name in names:
        name = name.rstrip(".,:;")
        if name.startswith(TOP) or name in TOP_FILES:
            if any(c in name for c in "<>*{}$"):   # patterns such as lib/include/avsplat/<module>/
                continue
            out.add(name.split(":")[0])
    return sorted(out)


@pytest.mark.parametrize("page", PAGES, ids=rel)
def test_named_paths_exist(page):
    missing = [p for p in named_paths(page) if not (ROOT / p).exists()]
    assert not missing, f"{rel(page)} names paths that do not exist: {missing}"


def test_the_path_check_sees_paths():
    # The check above must find the paths of a page that names some, or it could pass vacuously.
    assert "scripts/setup.sh" in named_paths(ROOT / "README.md")
    assert "lib/include/avsplat/reduce/simplify.h" in named_paths(ROOT / "docs" / "design" / "reduction.md")
