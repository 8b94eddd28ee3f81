"""The cost tables of README.md and docs/COST.md are what the committed `hdrg cost` records render
(host_tools.bench.cost_tables): each table sits between its markers with the commands that measure
its records named in the text above it; a changed record makes the comparison fail; a missing or
garbled record is an error that names the file and the field.  No toolchain needed."""
import copy
import json
from pathlib import Path

import pytest

from host_tools import cli
from host_tools.bench import cost_tables as T

ROOT = Path(__file__).resolve().parents[1]
EXPECTED = {"README.md": {"cortex-m4", "fpga"},
            "docs/COST.md": {"cortex-m4-measured", "cortex-m4-stages", "cortex-m4-mix", "fpga-measured", "goals"}}
BLOCKS = [(doc, b) for doc in T.DOCS for b in T.blocks((ROOT / doc).read_text(encoding="utf-8"), doc)]


@pytest.fixture(scope="module")
def records():
    return T.load_records()


def _edited(recs, target, field, value=None, delete=False):
    """A copy of ``recs`` whose ``target`` record has ``field`` (dotted) set to ``value`` or deleted."""
    out = dict(recs)
    data = copy.deepcopy(recs[target].data)
    *parents, last = field.split(".")
    d = data
    for p in parents:
        d = d[p]
    if delete:
        del d[last]
    else:
        d[last] = value
    out[target] = T.Record(data, recs[target].path)
    return out


def test_each_document_holds_its_tables_and_every_table_is_in_a_document():
    found = {doc: {b[0] for d, b in BLOCKS if d == doc} for doc in T.DOCS}
    assert found == EXPECTED
    assert set().union(*EXPECTED.values()) == set(T.TABLES)
    assert len(BLOCKS) == len(T.TABLES), "a table is marked twice"


@pytest.mark.parametrize("doc,block", BLOCKS, ids=[f"{d}:{b[0]}" for d, b in BLOCKS])
def test_the_table_between_the_markers_is_what_its_records_render(doc, block, records):
    name, head, body, _, _ = block
    assert head == T.marker(name), f"{doc}: the marker of {name} does not name the commands of its records"
    assert body == T.render(name, records), (
        f"{doc}: the {name} table differs from what its records render; after re-measuring run "
        f"`hdrg cost --fill README.md docs/COST.md`")


@pytest.mark.parametrize("doc,block", BLOCKS, ids=[f"{d}:{b[0]}" for d, b in BLOCKS])
def test_the_commands_are_in_the_text_right_above_the_table(doc, block):
    name, _, _, first, _ = block
    lines = (ROOT / doc).read_text(encoding="utf-8").split("\n")[:first]
    while lines and not lines[-1].strip():
        lines.pop()
    para = []
    while lines and lines[-1].strip():
        para.insert(0, lines.pop())
    text = " ".join(" ".join(para).split())
    for cmd in T.commands(name):
        assert f"`{cmd}`" in text, f"{doc}: `{cmd}` is not in the paragraph above the {name} table"


def test_the_documents_are_unchanged_by_fill(records):
    for doc in T.DOCS:
        text = (ROOT / doc).read_text(encoding="utf-8")
        assert T.fill(text, records, doc) == text, doc


def test_readme_stays_short():
    assert len((ROOT / "README.md").read_text(encoding="utf-8").splitlines()) <= 300


def test_a_changed_record_number_fails_the_comparison(records):
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    cost = (ROOT / "docs/COST.md").read_text(encoding="utf-8")
    assert T.differences(readme, records) == [] and T.differences(cost, records) == []
    spec = records["cortex-m4"].get("builds.specialized.cycles_per_sample")
    changed = _edited(records, "cortex-m4", "builds.specialized.cycles_per_sample", spec + 7)
    assert [n for n, _ in T.differences(readme, changed)] == ["cortex-m4"]
    assert {n for n, _ in T.differences(cost, changed)} == {"cortex-m4-stages", "cortex-m4-mix", "goals"}
    luts = records["ice40"].get("luts", "int")
    changed = _edited(records, "ice40", "luts", luts - 1)
    assert [n for n, _ in T.differences(readme, changed)] == ["fpga"]
    # a goal judged from the number: under the goal it says met
    changed = _edited(records, "cortex-m4", "builds.specialized.cycles_per_sample", T.M4_SPECIALIZED_CYCLES_GOAL - 1.0)
    assert f"(goal {T.M4_SPECIALIZED_CYCLES_GOAL}: met)" in T.render("cortex-m4", changed)
    assert f"(goal {T.M4_SPECIALIZED_CYCLES_GOAL}: missed)" in T.render("cortex-m4", records)
    changed = _edited(records, "cortex-m4", "builds.lean.cycles_per_sample", T.M4_CYCLES_GOAL - 1.0)
    assert f"(goal {T.M4_CYCLES_GOAL}: met)" in T.render("cortex-m4", changed)
    assert f"(goal {T.M4_CYCLES_GOAL}: missed)" in T.render("cortex-m4", records)


def test_a_stale_marker_or_an_unended_table_is_found(records):
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    stale = readme.replace("--json docs/studies/cost_cortex-m4.json) -->", "--json m4.json) -->")
    assert stale != readme
    assert [(n, why.split(" ")[0]) for n, why in T.differences(stale, records)] == [("cortex-m4", "marker")]
    with pytest.raises(T.RecordError, match="not of the form"):
        T.blocks(readme.replace(T.marker("cortex-m4"), "<!-- cost-table: cortex-m4 -->"), "README.md")
    open_only = readme.replace(T.END, "", 1)
    with pytest.raises(T.RecordError, match=r"README.md, line \d+: cost table cortex-m4 has no"):
        T.blocks(open_only, "README.md")
    unknown = readme.replace("<!-- cost-table: fpga (", "<!-- cost-table: fpga2 (")
    with pytest.raises(T.RecordError, match="unknown cost table 'fpga2'"):
        T.blocks(unknown, "README.md")


def test_a_missing_field_names_the_file_and_the_field(records):
    broken = _edited(records, "cortex-m4", "builds.specialized.code_bytes", delete=True)
    with pytest.raises(T.RecordError) as exc:
        T.render("cortex-m4", broken)
    msg = str(exc.value)
    assert "docs/studies/cost_cortex-m4.json" in msg and "builds.specialized.code_bytes" in msg and "missing" in msg
    wrong = _edited(records, "ice40", "luts", "many")
    with pytest.raises(T.RecordError, match=r"docs/studies/cost_ice40.json: field luts is \"many\", an integer expected"):
        T.render("fpga", wrong)


def test_a_missing_or_garbled_record_names_the_file(tmp_path):
    with pytest.raises(T.RecordError, match="nothing.json: cannot read the record"):
        T.load_records([tmp_path / "nothing.json"])
    bad = tmp_path / "cost_garbled.json"
    bad.write_text('{"target": "cortex-m4", "cycles_per_sample": ')
    with pytest.raises(T.RecordError, match=r"cost_garbled.json: not a JSON record of `hdrg cost` \(line 1"):
        T.load_records([bad])
    bad.write_text(json.dumps({"cycles_per_sample": 1}))
    with pytest.raises(T.RecordError, match="cost_garbled.json: field target is missing"):
        T.load_records([bad])
    bad.write_text("[1, 2]")
    with pytest.raises(T.RecordError, match="cost_garbled.json: not a record"):
        T.load_records([bad])


def test_cli_prints_the_tables_of_records_without_measuring(capsys, tmp_path):
    assert cli.main(["cost", "--tables"]) == 0
    out = capsys.readouterr().out
    assert all(T.marker(n) in out for n in T.TABLES) and out.count(T.END) == len(T.TABLES)
    # one record: only the tables it renders
    assert cli.main(["cost", "--tables", str(ROOT / T.record_path("cortex-m4"))]) == 0
    out = capsys.readouterr().out
    assert T.marker("cortex-m4") in out and "cost-table: fpga" not in out
    bad = tmp_path / "cost_garbled.json"
    bad.write_text("{")
    assert cli.main(["cost", "--tables", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "hdrg cost: error:" in err and "cost_garbled.json" in err and len(err.strip().splitlines()) == 1
    assert cli.main(["cost"]) == 2 and "--target" in capsys.readouterr().err


def test_cli_fill_rewrites_a_stale_table(capsys, tmp_path):
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    name, _, body, _, _ = T.blocks(readme, "README.md")[0]
    stale = readme.replace(body, "| build | cycles |\n|---|---|\n| generic | 643 |", 1)
    assert stale != readme
    doc = tmp_path / "README.md"
    doc.write_text(stale, encoding="utf-8")
    assert cli.main(["cost", "--fill", str(doc)]) == 0
    assert "rewritten" in capsys.readouterr().out
    assert doc.read_text(encoding="utf-8") == readme
