"""The index of the studies (docs/studies/README.md: claim -> command -> script -> record): every
file it names exists, every kept script compiles, imports no private name of the package and reads
no absolute path of a build machine; records are small."""
import ast
import py_compile
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ROOT / "docs" / "studies"
INDEX = STUDIES / "README.md"
PACKAGES = ("host_tools", "firmware_ref")
MACHINE_PATH = re.compile(r"(/(?:work|home|Users|tmp)/|[A-Za-z]:\\\\)")
MAX_RECORD_BYTES = 200_000


def index_rows() -> list:
    """(claim, command, script, record) per table row of the index."""
    rows = []
    for line in INDEX.read_text().splitlines():
        if not line.startswith("| ") or line.startswith("| claim ") or line.startswith("|---"):
            continue
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]
        assert len(cells) == 4, f"index row with {len(cells)} cells, 4 expected: {line}"
        rows.append(tuple(cells))
    return rows


def paths_in(cell: str) -> list:
    return [ROOT / p for p in re.findall(r"`(docs/studies/[^`\s]+)`", cell)]


ROWS = index_rows()
SCRIPTS = sorted({p for row in ROWS for p in paths_in(row[2])})


def test_the_index_has_rows_and_each_names_a_command_and_a_record():
    assert len(ROWS) >= 10
    for claim, command, script, record in ROWS:
        assert claim and "`" in command, (claim, command)
        assert paths_in(record), f"no record for: {claim}"
        if script != "-":
            assert paths_in(script), f"script cell names no file: {claim}"


@pytest.mark.parametrize("row", ROWS, ids=[r[0][:40] for r in ROWS])
def test_every_file_of_the_index_exists(row):
    for cell in row:
        for path in paths_in(cell):
            assert path.is_file(), f"{path.relative_to(ROOT)} named in docs/studies/README.md is missing"


def test_every_script_in_the_folder_is_in_the_index():
    kept = {p.resolve() for p in STUDIES.glob("*.py")}
    assert kept == {p.resolve() for p in SCRIPTS}, "a script in docs/studies/ is not in the index, or the reverse"


@pytest.mark.parametrize("script", SCRIPTS, ids=[p.name for p in SCRIPTS])
def test_each_script_compiles_and_uses_public_names_only(script, tmp_path):
    py_compile.compile(str(script), cfile=str(tmp_path / "x.pyc"), doraise=True)
    source = script.read_text()
    tree = ast.parse(source)
    modules = set()            # local names bound to a package module
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in PACKAGES:
            for alias in node.names:
                assert not alias.name.startswith("_"), f"{script.name} imports the private {node.module}.{alias.name}"
                modules.add(alias.asname or alias.name)
            assert not any(part.startswith("_") for part in node.module.split(".")), node.module
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in PACKAGES:
                    assert not any(part.startswith("_") for part in alias.name.split(".")), alias.name
                    modules.add(alias.asname or alias.name.split(".")[0])
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            base = node.value
            while isinstance(base, ast.Attribute):
                base = base.value
            assert not (isinstance(base, ast.Name) and base.id in modules), \
                f"{script.name} uses the private {ast.unparse(node)}"
    assert not MACHINE_PATH.search(source), f"{script.name} names an absolute path of a machine"


def test_records_are_small_and_name_no_machine_path():
    for path in STUDIES.iterdir():
        if path.suffix in (".json", ".jsonl", ".txt"):
            assert path.stat().st_size <= MAX_RECORD_BYTES, f"{path.name} is {path.stat().st_size} bytes"
            assert not MACHINE_PATH.search(path.read_text()), f"{path.name} names an absolute path of a machine"
