"""The documentation site's promises, checked cheaply (CI builds the site itself, warnings as
errors): every gallery example is one that the build executes, every page is in the site, the CLI
reference is generated from the real parser, and the README's build command is the one CI runs."""

import argparse
import ast
import re
import runpy
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
GALLERY = ROOT / "examples" / "gallery"


@pytest.fixture(scope="module")
def conf():
    return runpy.run_path(str(DOCS / "conf.py"))


def _examples():
    return sorted(GALLERY.glob("*.py"))


def test_the_gallery_has_at_least_eight_examples_and_the_build_executes_each(conf):
    gallery = conf["sphinx_gallery_conf"]
    assert Path(gallery["examples_dirs"]).resolve() == GALLERY
    assert (GALLERY / "README.rst").is_file()  # sphinx-gallery's index of the folder
    examples = _examples()
    assert len(examples) >= 8, [p.name for p in examples]
    pattern = re.compile(gallery["filename_pattern"])
    not_run = [p.name for p in examples if not pattern.search(str(p))]
    assert not not_run, f"not executed by the build (name them plot_*.py): {not_run}"


@pytest.mark.parametrize("path", _examples(), ids=lambda p: p.name)
def test_each_gallery_example_has_a_title_and_a_description(path):
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")), clean=False)
    assert doc is not None, f"{path.name}: sphinx-gallery needs a module docstring"
    lines = doc.strip("\n").splitlines()
    title, underline = lines[0], lines[1]
    assert set(underline) == {"="} and len(underline) >= len(title), (
        f"{path.name}: the title must be underlined with '=' at least as long as it"
    )
    assert len(lines) > 3 and lines[2] == "" and lines[3].strip(), f"{path.name}: no description"


def test_each_gallery_example_says_what_it_runs_in_cells():
    for path in _examples():
        text = path.read_text(encoding="utf-8")
        assert text.count("\n# %%\n") >= 1, f"{path.name}: no '# %%' cell separators"
        assert "import ivobs" in text or "from ivobs" in text, path.name


def test_the_cli_reference_is_generated_from_the_real_parser():
    page = (DOCS / "cli.rst").read_text()
    directive = re.search(r"\.\. argparse::\n((?:   :\w+: .+\n)+)", page)
    assert directive, "cli.rst must use the argparse directive"
    opts = dict(re.findall(r"   :(\w+): (.+)", directive.group(1)))
    assert opts["module"] == "ivobs.cli" and opts["func"] == "build_parser"
    assert opts["prog"] == "ivobs"
    import ivobs.cli

    parser = getattr(ivobs.cli, opts["func"])()
    assert isinstance(parser, argparse.ArgumentParser) and parser.prog == "ivobs"
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert {"run", "compare", "monitor", "campaign", "figures"} <= set(sub.choices)


def _toctree_entries():
    entries = set()
    for page in DOCS.rglob("*.md"):
        if "_build" in page.parts or "auto_examples" in page.parts:
            continue
        for block in re.findall(r"```\{toctree\}\n(.*?)```", page.read_text(), flags=re.S):
            for line in block.splitlines():
                if line.strip() and not line.startswith(":"):
                    entries.add((page.parent / line.strip()).relative_to(DOCS).as_posix())
    return entries


def test_every_docs_page_is_in_the_site():
    pages = {
        p.relative_to(DOCS).with_suffix("").as_posix()
        for p in [*DOCS.rglob("*.md"), *DOCS.rglob("*.rst")]
        if "_build" not in p.parts and "auto_examples" not in p.parts
    }
    pages -= {"index", "sg_execution_times"}
    listed = _toctree_entries()
    for rst in DOCS.rglob("*.rst"):
        if "_build" in rst.parts or "auto_examples" in rst.parts:
            continue
        toctree = r"\.\. toctree::\n(?:   :.*\n)*\n((?:   \S.*\n)+)"
        for block in re.findall(toctree, rst.read_text()):
            listed |= {(rst.parent / e.strip()).relative_to(DOCS).as_posix() for e in block.split()}
    assert pages <= listed, f"pages in no toctree: {sorted(pages - listed)}"


def test_the_api_reference_covers_the_public_packages_and_every_method():
    import ivobs
    from ivobs.estimators import get

    api = "\n".join(p.read_text() for p in (DOCS / "api").glob("*.rst"))
    for module in ["ivobs", "ivobs.io", "ivobs.monitor", "ivobs.scenarios", "ivobs.report",
                   "ivobs.campaign", "ivobs.sets", "ivobs.estimators"]:  # fmt: skip
        assert f".. automodule:: {module}\n" in api, module
    for name in ivobs.methods():
        cls = get(name)
        assert f".. autoclass:: {cls.__module__}.{cls.__qualname__}\n" in api or (
            f".. autoclass:: {cls.__module__.rsplit('.', 1)[0]}.{cls.__qualname__}\n" in api
        ), f"method {name!r} ({cls.__qualname__}) is not in docs/api/estimators.rst"


def test_the_readme_build_command_is_the_one_ci_runs_and_the_docs_extra_has_its_tools(conf):
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Documentation", 1)[1].split("\n## ", 1)[0]
    (command,) = re.findall(r"```sh\n(.*?)\n```", section, flags=re.S)
    install, build = (part.strip() for part in command.split("&&"))
    assert install == 'pip install ".[docs]"' and build.startswith("sphinx-build -W --keep-going")
    assert build in (ROOT / ".ci" / "run").read_text()
    pyproject = (ROOT / "pyproject.toml").read_text()
    extra = re.search(r"^docs = \[(.*?)\]", pyproject, flags=re.S | re.M).group(1)
    needed = {"sphinx", "myst-parser", "numpydoc", "sphinx-gallery", "sphinx-argparse"}
    listed = set(re.findall(r'"([a-z0-9-]+)(?:\[[^]]*\])?>=', extra))
    assert needed <= listed, needed - listed
    assert conf["html_theme"].replace("_", "-") in listed
    assert "docs/_build/" in (ROOT / ".gitignore").read_text().splitlines()
