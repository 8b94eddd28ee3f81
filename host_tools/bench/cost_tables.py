"""The cost tables of README.md and docs/COST.md, rendered from the records of `hdrg cost`.

Each table is rendered from committed records (``docs/studies/cost_<target>.json``, written by
``hdrg cost --target <target> --json docs/studies/cost_<target>.json``) and sits in its document
between two markers that name the table and the commands that measure its records::

    <!-- cost-table: cortex-m4 (hdrg cost --target cortex-m4 --json docs/studies/cost_cortex-m4.json) -->
    | ... the rendered table ... |
    <!-- /cost-table -->

`hdrg cost --tables [RECORD ...]` prints the tables (with their markers) of the records,
`hdrg cost --fill FILE ...` rewrites the marked tables of documents in place, and
tests/test_cost_tables.py checks that the documents hold exactly what the committed records render.

Units: cycles are per sample (Cortex-M4: the mean of the nominal per-instruction model over the traced
samples, host_tools.bench.cost_m4_model.M4_MODEL; FPGA: clock cycles of the RTL, the worst or the mean over a
vector set's sample requests), code and stack in bytes, vectors are compared vectors, FPGA resources
are Yosys cells (LUT4 / LUT, flip-flops, DSP and block-RAM cells), Fmax in MHz (nextpnr-ice40).
A goal is judged from the record's numbers (``met`` / ``missed``), never copied.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

from host_tools.bench.cost_fpga import CYCLES_GOAL, FMAX_GOAL_MHZ, UP5K, UP5K_LUT_AIM
from host_tools.errors import UserError

ROOT = Path(__file__).resolve().parent.parent.parent
STUDIES = "docs/studies"
M4_CYCLES_GOAL = 300                    # Cortex-M4: cycles per sample of the firmware entry point (hdrg_step_out)
M4_SPECIALIZED_CYCLES_GOAL = 200        # Cortex-M4: cycles per sample of the build specialized to the default configuration
M4_CODE_GOAL = 4096                     # Cortex-M4: bytes of per-sample code at -Os (4 KiB), firmware entry point
DOCS = ("README.md", "docs/COST.md")    # the documents whose tables tests/test_cost_tables.py checks
END = "<!-- /cost-table -->"
_OPEN = re.compile(r"^<!-- cost-table: (\S+) \((.*)\) -->$")


class RecordError(UserError):
    """A record of `hdrg cost` that cannot be read or lacks a field a table needs (the message names
    the file and the field), or a document whose markers are broken."""


def record_path(target: str) -> str:
    """The committed record of ``target``, relative to the repository root."""
    return f"{STUDIES}/cost_{target}.json"


def command(target: str) -> str:
    """The command that measures ``target`` and writes its committed record."""
    return f"hdrg cost --target {target} --json {record_path(target)}"


# -- records -------------------------------------------------------------------------------------------

class Record:
    """One record of `hdrg cost` (the JSON it writes) and the file it came from; :meth:`get` reads a
    field by its dotted path (``builds.lean.cycles_per_sample``) and checks its kind."""

    KINDS = {"int": "an integer", "num": "a number", "num?": "a number or null", "bool": "true or false",
             "str": "a string", "dict": "an object", "list": "a list"}

    def __init__(self, data: dict, path):
        self.data, self.path = data, _shown(path)
        if not isinstance(data, dict):
            raise RecordError(f"{self.path}: not a record of `hdrg cost` (a JSON object expected)")
        self.target = self.get("target", "str")

    def has(self, field: str) -> bool:
        """Whether the dotted path ``field`` is in the record."""
        value = self.data
        for part in field.split("."):
            if not isinstance(value, dict) or part not in value:
                return False
            value = value[part]
        return True

    def get(self, field: str, kind: str = "num"):
        """The value at the dotted path ``field``; a RecordError naming the file and the field when it is
        missing or not of ``kind`` (int, num, num?, bool, str, dict, list)."""
        value = self.data
        for part in field.split("."):
            if not isinstance(value, dict) or part not in value:
                raise RecordError(f"{self.path}: field {field} is missing "
                                  f"(re-run `{command(self.data.get('target', 'TARGET'))}`)")
            value = value[part]
        ok = {"int": lambda v: isinstance(v, int) and not isinstance(v, bool),
              "num": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
              "num?": lambda v: v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)),
              "bool": lambda v: isinstance(v, bool), "str": lambda v: isinstance(v, str),
              "dict": lambda v: isinstance(v, dict), "list": lambda v: isinstance(v, list)}[kind]
        if not ok(value):
            raise RecordError(f"{self.path}: field {field} is {json.dumps(value)[:60]}, {self.KINDS[kind]} expected")
        return value


def _shown(path) -> str:
    p = Path(path)
    try:
        return str(p.resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def load(path) -> Record:
    """Read one record; a RecordError naming the file when it is missing, not JSON or has no target."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise RecordError(f"{_shown(path)}: cannot read the record ({exc.strerror or exc})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RecordError(f"{_shown(path)}: not a JSON record of `hdrg cost` (line {exc.lineno}: {exc.msg})") from None
    return Record(data, path)


def load_records(paths=None) -> dict:
    """target -> Record of ``paths`` (default: the committed records of every table's targets)."""
    if paths is None:
        targets = sorted({t for ts, _ in TABLES.values() for t in ts})
        paths = [ROOT / record_path(t) for t in targets]
    out = {}
    for p in paths:
        r = load(p)
        if r.target in out:
            raise RecordError(f"{r.path}: a second record of target {r.target} (the first: {out[r.target].path})")
        out[r.target] = r
    return out


# -- number formats ------------------------------------------------------------------------------------

def _i(x) -> str:
    """An integer count with thousands separators (vectors, bytes, cells, cycles rounded)."""
    return f"{round(x):,}"


def _d(x) -> str:
    """One decimal with thousands separators (mean instructions or cycles per sample)."""
    return f"{x:,.1f}"


def _judge(value, goal, at_most: bool = True) -> str:
    return "met" if (value <= goal if at_most else value >= goal) else "missed"


def _table(header, rows) -> str:
    """A markdown table ('|' inside a cell escaped)."""
    def line(cells):
        return "|" + "|".join(f" {c} ".replace("|", "\\|") if str(c) else " " for c in cells) + "|"
    return "\n".join([line(header), "|" + "---|" * len(header), *(line(r) for r in rows)])


# -- Cortex-M4 -----------------------------------------------------------------------------------------

GENERIC = ("-O2.", "-Os.")               # the generic build's bit_exact fields (-O2 and -Os)


def _bit_exact(r: Record, prefixes, what: str) -> str:
    """``what`` when every ``<prefix>bit_exact`` of the record is true, else says it is not bit-exact."""
    ok = all(r.get(f"{p}bit_exact", "bool") for p in ((prefixes,) if isinstance(prefixes, str) else prefixes))
    return what if ok else f"**not bit-exact** ({what} compared)"


def readme_m4(recs: dict) -> str:
    """README: cycles per sample (nominal model, mean over the e2e samples traced, -O2), per-sample code
    bytes at -Os and the vectors checked, of the generic build (hdrg_step_aux), the firmware entry point
    (hdrg_step_out) and the build specialized to the default configuration; goals: the firmware entry
    point 300 cycles and 4 KiB, the specialized build 200 cycles."""
    r = recs["cortex-m4"]
    spec, lean = "builds.specialized.", "builds.lean."
    lcyc, lcode = r.get(lean + "cycles_per_sample"), r.get(lean + "code_bytes", "int")
    rows = [["generic (`hdrg_step_aux`, every intermediate)", _i(r.get("cycles_per_sample")),
             f"{_i(r.get('code_bytes', 'int'))} B", _bit_exact(r, GENERIC, f"{_i(r.get('-O2.vectors', 'int'))} vectors")],
            ["firmware entry point (`hdrg_step_out`)",
             f"**{_i(lcyc)}** (goal {M4_CYCLES_GOAL}: {_judge(lcyc, M4_CYCLES_GOAL)})",
             f"**{_i(lcode)} B** (goal {M4_CODE_GOAL // 1024} KiB: {_judge(lcode, M4_CODE_GOAL)})",
             _bit_exact(r, lean, f"{_i(r.get(lean + 'vectors', 'int'))} vectors")]]
    cyc, code = r.get(spec + "cycles_per_sample"), r.get(spec + "code_bytes", "int")
    rows.append(["specialized to the default configuration",
                 f"**{_i(cyc)}** (goal {M4_SPECIALIZED_CYCLES_GOAL}: {_judge(cyc, M4_SPECIALIZED_CYCLES_GOAL)})",
                 f"**{_i(code)} B**",
                 _bit_exact(r, spec, f"its {_i(r.get(spec + 'vectors', 'int'))} vectors; the other "
                            f"{_i(r.get(spec + '-O2.check.tables_refused', 'int'))} tables refused")])
    return _table(["build", "cycles / sample (QEMU, cycle model, e2e mean)", "per-sample code, -Os", "bit-exact"],
                  rows)


def _cycles_cell(r: Record, base: str, bold: bool = True) -> str:
    """``N instr. (max M), C cycles (low..high, max X)`` of a per_sample block (means per sample)."""
    c = f"{_d(r.get(base + 'cycles_m4_model.nominal.mean'))} cycles"
    return (f"{_d(r.get(base + 'instructions.mean'))} instr. (max {_i(r.get(base + 'instructions.max'))}), "
            f"{'**' + c + '**' if bold else c} ({_d(r.get(base + 'cycles_m4_model.low.mean'))}.."
            f"{_d(r.get(base + 'cycles_m4_model.high.mean'))}, max {_i(r.get(base + 'cycles_m4_model.nominal.max'))})")


def _caught(r: Record, prefix: str) -> str:
    return "broken build caught" if r.get(prefix + "broken_build_caught", "bool") else "**broken build not caught**"


def cost_m4(recs: dict) -> str:
    """docs/COST.md "Measured": every Cortex-M4 figure of the record: vectors checked per build, mean
    instructions and cycles per sample (nominal model; low..high model, max of one sample) per build and
    workload, code bytes (per-sample path, library text), stack bytes (worst call path of a sample)."""
    r = recs["cortex-m4"]
    lean, spec = "builds.lean.", "builds.specialized."
    n_cases = len(r.get("-O2.per_sample.e2e.per_case", "dict"))
    spec_cases = r.get(spec + "e2e_cases", "list")
    fields = " ".join(r.get(lean + "fields", "list"))
    def yes(prefixes):
        return "yes" if _bit_exact(r, prefixes, "yes") == "yes" else "**no**"

    na = "-Os-no-aux-gen."
    rows = [
        ["bit-exact, generic (`hdrg_step_aux`, -O2 and -Os)",
         f"{yes(GENERIC)}: {_i(r.get('-O2.vectors', 'int'))} vectors; {_caught(r, '')}"],
        ["bit-exact, lean (`hdrg_step_out`, -O2 and -Os)",
         f"{yes(lean)}: {_i(r.get(lean + 'vectors', 'int'))} (O fields {fields}); {_caught(r, lean)}"],
        ["bit-exact, specialized (-O2 and -Os)",
         f"{yes(spec)}: {_i(r.get(spec + 'vectors', 'int'))} vectors of the accepted tables, the other "
         f"{_i(r.get(spec + '-O2.check.tables_refused', 'int'))} tables refused; {_caught(r, spec)}"],
        [f"**generic**, e2e all {n_cases} cases, -O2", _cycles_cell(r, "-O2.per_sample.e2e.")],
        ["generic, -Os, e2e", _cycles_cell(r, "-Os.per_sample.e2e.", bold=False)],
        [f"**lean** (firmware entry point), e2e all {len(r.get(lean + 'e2e_cases', 'list'))} cases, -O2",
         _cycles_cell(r, lean + "per_sample.")],
        [f"**specialized**, the {len(spec_cases)} e2e cases it accepts"
         + (f" ({spec_cases[0]} ...)" if spec_cases else "") + ", -O2",
         _cycles_cell(r, spec + "per_sample.")],
        ["with aux generators (aux-sim, generic, -O2 / -Os)",
         f"{_d(r.get('-O2.per_sample.aux-sim.instructions.mean'))} instr., "
         f"{_d(r.get('-O2.per_sample.aux-sim.cycles_m4_model.nominal.mean'))} cycles / "
         f"{_d(r.get('-Os.per_sample.aux-sim.instructions.mean'))} instr., "
         f"{_d(r.get('-Os.per_sample.aux-sim.cycles_m4_model.nominal.mean'))} cycles"],
        ["per-sample code, -Os (generic / lean / specialized)",
         f"**{_i(r.get('code_bytes', 'int'))} / {_i(r.get(lean + 'code_bytes', 'int'))} / "
         f"{_i(r.get(spec + 'code_bytes', 'int'))} B**"],
        ["per-sample code, -O2 (generic / lean / specialized)",
         f"{_i(r.get('code_bytes_O2', 'int'))} / {_i(r.get(lean + '-O2.code_bytes', 'int'))} / "
         f"{_i(r.get(spec + '-O2.code_bytes', 'int'))} B"],
        ["per-sample code, -Os, generic without aux generators (`-DHDRG_AUX_GEN=0`)",
         f"{_i(r.get('code_bytes_no_aux_gen', 'int'))} B; "
         + ("bit-exact" if r.get(na + "bit_exact", "bool") else "**not bit-exact**") + " on the "
         f"{_i(r.get(na + 'vectors', 'int'))} vectors of {', '.join(r.get(na + 'sets', 'list'))}; aux tables "
         + ("refused" if r.get(na + "aux_tables_refused", "bool") else "**not refused**")],
        ["library text, -Os / -O2 (generic)",
         f"{_i(r.get('-Os.library.text', 'int'))} / {_i(r.get('-O2.library.text', 'int'))} B"],
        ["stack, a sample, -O2 (generic / lean / specialized); a table load",
         f"{_i(r.get('stack_bytes', 'int'))} / {_i(r.get(lean + '-O2.stack_step_bytes', 'int'))} / "
         f"{_i(r.get(spec + '-O2.stack_step_bytes', 'int'))} B; {_i(r.get('-O2.stack_init_bytes', 'int'))} B"],
        ["tools", "; ".join(str(v) for v in r.get("tools", "dict").values())],
    ]
    return _table(["", f"Cortex-M4 (QEMU `{r.get('machine', 'str')}`)"], rows)


STAGE_NAMES = {"step": "step glue", "combiner": "combiner (incl. window commits)"}
STAGE_ORDER = ("evaluator", "step", "rate", "combiner", "proxy", "aux", "sequencer", "primitives", "table parser")


def cost_m4_stages(recs: dict) -> str:
    """docs/COST.md: per stage, mean instructions / nominal cycles per sample (-O2, from the traces'
    inline chains) of the generic, lean and specialized builds on e2e and of the generic build on the
    aux set's simulated case; code bytes per stage of the -O2 -fno-inline object."""
    r = recs["cortex-m4"]
    cols = [("per_stage.e2e.instructions_mean", "per_stage.e2e.cycles_nominal_mean"),
            ("builds.lean.per_sample.per_stage_instructions", "builds.lean.per_sample.per_stage_cycles"),
            ("builds.specialized.per_sample.per_stage_instructions", "builds.specialized.per_sample.per_stage_cycles"),
            ("per_stage.aux-sim.instructions_mean", "per_stage.aux-sim.cycles_nominal_mean")]
    data = [(r.get(i, "dict"), r.get(c, "dict")) for i, c in cols]
    code = r.get("code_bytes_per_stage_noinline", "dict")
    names = [s for s in STAGE_ORDER if any(s in d[0] for d in data) or s in code]
    names += [s for d in data for s in d[0] if s not in names]
    names += [s for s in code if s not in names]
    rows = []
    for s in names:
        row = [STAGE_NAMES.get(s, s)]
        for (ins, cyc), (ins_d, _) in zip(cols, data):
            row.append(f"{_d(r.get(f'{ins}.{s}'))} / {_d(r.get(f'{cyc}.{s}'))}" if s in ins_d else "-")
        row.append(_i(r.get(f"code_bytes_per_stage_noinline.{s}", "int")) if s in code else "-")
        rows.append(row)
    totals = [(r.get("per_stage.e2e.total_instructions_mean"),
               r.get("-O2.per_sample.e2e.cycles_m4_model.nominal.mean")),
              (r.get("builds.lean.instructions_per_sample"), r.get("builds.lean.cycles_per_sample")),
              (r.get("builds.specialized.instructions_per_sample"), r.get("builds.specialized.cycles_per_sample")),
              (r.get("per_stage.aux-sim.total_instructions_mean"),
               r.get("-O2.per_sample.aux-sim.cycles_m4_model.nominal.mean"))]
    rows.append(["total (a sample)", *(f"{_d(a)} / {_d(b)}" for a, b in totals), _i(sum(code.values()))])
    return _table(["stage", "generic, e2e", "lean, e2e", "specialized, its e2e cases", "generic, aux-sim",
                   "code bytes (-O2 -fno-inline)"], rows)


def cost_m4_mix(recs: dict) -> str:
    """docs/COST.md: the firmware builds' instruction mix per sample (host_tools.bench.cost_m4_model.instruction_mix,
    mean over their e2e traces), the flash fetch events and the nominal cycles with code in flash of
    1, 2 and 5 wait states, a prefetch buffer and no cache (an upper bound; the other tables' cycles
    assume zero wait states)."""
    from host_tools.bench.cost_m4_model import FLASH_WAIT_STATES, MIX_CLASSES

    r = recs["cortex-m4"]
    builds = (("lean", "firmware entry point"), ("specialized", "specialized"))
    rows = [[k, *(_d(r.get(f"builds.{b}.per_sample.mix.{k}")) for b, _ in builds)] for k in MIX_CLASSES]
    rows.append(["instructions", *(_d(r.get(f"builds.{b}.instructions_per_sample")) for b, _ in builds)])
    rows.append(["cycles, zero wait states (the model)", *(_d(r.get(f"builds.{b}.cycles_per_sample")) for b, _ in builds)])
    rows.append(["flash fetch events (taken branches, returns, literal loads)",
                 *(_d(r.get(f"builds.{b}.per_sample.flash_events")) for b, _ in builds)])
    rows += [[f"cycles, flash with {w} wait state{'s' if w > 1 else ''}, prefetch buffer, no cache (upper bound)",
              *(_d(r.get(f"builds.{b}.per_sample.cycles_flash_no_cache.{w}")) for b, _ in builds)]
             for w in FLASH_WAIT_STATES]
    return _table(["per sample (e2e, -O2)", *(label for _, label in builds)], rows)


# -- FPGA ----------------------------------------------------------------------------------------------

def _sim(r: Record) -> str:
    """The simulator whose run covers every vector of the record: Verilator for the SoC (Icarus runs a
    subset of it), Icarus for the dedicated RTL."""
    return "verilator" if r.has("firmware") else "icarus"


def _fpga_cycles(r: Record) -> tuple:
    """(worst cycles per sample over the sets without 16-term aux tables, the sets, worst on the aux set)."""
    sim = _sim(r)
    sets = r.get(sim, "dict")
    other = {n: r.get(f"{sim}.{n}.cycles_max", "int") for n in sets
             if n != "aux" and r.get(f"{sim}.{n}.samples", "int")}
    return max(other.values()), list(other), r.get(f"{sim}.aux.cycles_max", "int")


def _rate(r: Record) -> str:
    """The highest output rate at FMAX_GOAL_MHZ (one sample per worst-case sample time): with the e2e
    set's tables (the default 17-term mode-reversal pipeline) and with any table of the vectors."""
    sim, worst = _sim(r), r.get("cycles_per_sample", "int")
    e2e = r.get(f"{sim}.e2e.cycles_max", "int")
    hz = lambda c: _i(int(FMAX_GOAL_MHZ * 1e6 // c))
    return (f"{hz(e2e)} samples/s at {FMAX_GOAL_MHZ:g} MHz with the e2e tables ({_i(e2e)} cycles), {hz(worst)} with "
            f"any table of the vectors ({_i(worst)} cycles)")


def _soc_exact(r: Record) -> str:
    """Bit-exactness of the SoC: Verilator on every vector, Icarus on the first vectors of every case."""
    sets = r.get("verilator", "dict")
    per = ", ".join(f"{n} {_i(r.get(f'verilator.{n}.vectors', 'int'))}" for n in sets)
    bad_v = sum(r.get(f"verilator.{n}.mismatches", "int") for n in sets)
    bad_i = sum(r.get(f"icarus.{n}.mismatches", "int") for n in r.get("icarus", "dict"))
    return (f"Verilator, every vector: {_i(r.get('vectors', 'int'))} ({per}), {_i(bad_v)} mismatches; Icarus, the "
            f"first {r.get('icarus_first_rows', 'int')} vectors of every {' and '.join(r.get('icarus', 'dict'))} case: "
            f"{_i(r.get('icarus_vectors', 'int'))}, {_i(bad_i)} mismatches")


def _resources(r: Record, base: str = "") -> str:
    """``N LUT4 / F FF / D SB_MAC16 / B BRAM`` (iCE40) or ``N LUT / ... / DSP48E1 / RAMB18 + RAMB36 +
    LUTRAM`` (7-series), from the record's Yosys cells."""
    luts, ffs, dsps = (_i(r.get(base + k, "int")) for k in ("luts", "ffs", "dsps"))
    if r.target == "ice40":
        spram = r.get(base + "sprams", "int") if r.has(base + "sprams") else 0
        return (f"{luts} LUT4 / {ffs} FF / {dsps} SB_MAC16 / {_i(r.get(base + 'brams', 'int'))} SB_RAM40_4K"
                + (f" / {spram} SB_SPRAM256KA" if spram else ""))
    cells = r.get(base + "cells", "dict")
    ram = [f"{cells[c]} {c[:6]}" for c in ("RAMB18E1", "RAMB36E1") if cells.get(c)]
    if r.get(base + "lutrams", "int"):
        ram.append(f"{_i(r.get(base + 'lutrams', 'int'))} LUTRAM")
    return f"{luts} LUT / {ffs} FF / {dsps} DSP48E1" + (" / " + " + ".join(ram) if ram else "")


def _fmax(r: Record, goal: bool = True) -> str:
    """Fmax of the whole pipeline in MHz (nextpnr-ice40), with the goal when ``goal``; why there is none."""
    if r.target != "ice40":
        return "n/a (no open place-and-route for 7-series)"
    if r.get("pnr.fits", "bool"):
        f = r.get("fmax_mhz")
        return f"{f:.2f} MHz" + (f" (goal {FMAX_GOAL_MHZ:g}: {_judge(f, FMAX_GOAL_MHZ, at_most=False)})" if goal else "")
    used, avail = r.get("pnr.utilisation.ICESTORM_LC", "list")
    return f"not placed: nextpnr-ice40 `--up5k` needs {_i(used)} logic cells of {_i(avail)}"


def _mhz(r: Record, field: str) -> str:
    """A field of Fmax in MHz (null: not placed)."""
    f = r.get(field, "num?")
    return "not placed" if f is None else f"{f:.2f} MHz"


def _design(r: Record) -> str:
    return ("the C twin on PicoRV32 (`hdrg_soc`)" if r.has("firmware")
            else f"dedicated RTL `hdrg_top` (N_HIST {r.get('n_hist', 'int')})")


def _cycles_text(r: Record) -> str:
    """Worst and mean clock cycles per sample on the e2e set, and the worst on the aux set."""
    sim = _sim(r)
    return (f"{_i(r.get(f'{sim}.e2e.cycles_max', 'int'))} worst, {_d(r.get(f'{sim}.e2e.cycles_mean'))} mean on the "
            f"e2e set (the 17-term mode-reversal tables), {_i(r.get(f'{sim}.aux.cycles_max', 'int'))} worst on the "
            f"aux set (up to 16 aux terms)")


def readme_fpga(recs: dict) -> str:
    """README: the whole pipeline on iCE40 UP5K (the SoC) and 7-series (the dedicated RTL): design,
    vectors checked, worst clock cycles per sample and the highest output rate at 24 MHz, Yosys cells
    (UP5K: of 5,280 LUT4) and Fmax in MHz, the evaluator alone (LUT4, Fmax in MHz, cycles per sample)."""
    cols = [recs["ice40"], recs["xc7"]]

    def exact(r):
        if r.has("firmware"):
            return (f"{_bit_exact(r, '', _i(r.get('vectors', 'int')) + ' vectors')} (Verilator; Icarus: the first "
                    f"{r.get('icarus_first_rows', 'int')} of every {' and '.join(r.get('icarus', 'dict'))} case)")
        return _bit_exact(r, "", f"{_i(r.get('vectors', 'int'))} vectors") + " (Icarus and Verilator)"

    def res(r):
        if r.target == "ice40":
            luts = r.get("luts", "int")
            return (f"{_i(luts)} LUT4 (of {_i(UP5K['luts'])}) / {_i(r.get('dsps', 'int'))} SB_MAC16 / "
                    f"{_i(r.get('brams', 'int'))} EBR / {_i(r.get('sprams', 'int'))} SPRAM; {_fmax(r, goal=False)}")
        return " / ".join(p for p in _resources(r).split(" / ") if not p.endswith(" FF"))

    def alone(r):
        e = "evaluator_alone."
        lut = f"{_i(r.get(e + 'luts', 'int'))} LUT" + ("4" if r.target == "ice40" else "")
        if r.target != "ice40":
            return lut
        return f"{lut}, {_mhz(r, e + 'fmax_mhz')}, {r.get(e + 'cycles_per_sample', 'int')} cycles"

    rows = [["bit-exact", *(exact(r) for r in cols)],
            ["cycles / sample (worst); highest output rate", *(f"{_cycles_text(r)}; {_rate(r)}" for r in cols)],
            ["resources", *(res(r) for r in cols)],
            ["the dedicated RTL's evaluator alone", *(alone(r) for r in cols)]]
    return _table(["", f"iCE40 UP5K: {_design(cols[0])}", f"Xilinx 7-series: {_design(cols[1])}"], rows)


def cost_fpga(recs: dict) -> str:
    """docs/COST.md "Measured": every FPGA figure of the ice40 (SoC) and xc7 (dedicated RTL) records:
    vectors per set and mismatches per simulator, the broken build, worst and mean clock cycles per
    sample per set, the highest output rate, Yosys cells (LUT, FF, DSP, BRAM, SPRAM), Fmax in MHz
    (nextpnr-ice40), the firmware image, the evaluator alone, the tools."""
    cols = [recs["ice40"], recs["xc7"]]

    def exact(r):
        if r.has("firmware"):
            return _soc_exact(r)
        sets = r.get("icarus", "dict")
        per = ", ".join(f"{n} {_i(r.get(f'icarus.{n}.vectors', 'int'))}" for n in sets)
        bad = sum(r.get(f"{sim}.{n}.mismatches", "int") for sim in ("icarus", "verilator") for n in sets)
        return f"Icarus and Verilator, every vector: {_i(r.get('vectors', 'int'))} ({per}), {_i(bad)} mismatches"

    def broken(r):
        if not r.get("broken_build_caught", "bool"):
            return "**not caught**"
        if r.has("firmware"):
            return (f"firmware built with it: caught, {_i(r.get('broken_build_mismatches', 'int'))} of "
                    f"{_i(r.get('broken_build_vectors', 'int'))} {r.get('broken_build_set', 'str')} vectors (the first "
                    f"{r.get('broken_build_first_rows', 'int')} of every case) differ")
        return (f"caught: {_i(r.get('broken_build_mismatches', 'int'))} of "
                f"{_i(r.get('icarus.sequencer.vectors', 'int'))} sequencer vectors differ")

    def cycles(r):
        sim = _sim(r)
        sets = [n for n in r.get(sim, "dict") if r.get(f"{sim}.{n}.samples", "int")]
        return (f"({sim}) worst " + ", ".join(f"{n} {_i(r.get(f'{sim}.{n}.cycles_max', 'int'))}" for n in sets)
                + "; mean " + ", ".join(f"{n} {_d(r.get(f'{sim}.{n}.cycles_mean'))}" for n in sets))

    def firmware(r):
        if not r.has("firmware"):
            return "-"
        return (f"{_i(r.get('firmware.rom_bytes', 'int'))} B of a {_i(r.get('firmware.rom_capacity_bytes', 'int'))} B "
                f"ROM (RV32IMC, -Os; {r.get('tools.picorv32', 'str')})")

    def alone(r):
        e = "evaluator_alone."
        s = _resources(r, e)
        if r.target == "ice40":
            s += f", {_mhz(r, e + 'fmax_mhz')} (nextpnr)"
        return (s + f", {r.get(e + 'cycles_per_sample', 'int')} cycles; "
                + _bit_exact(r, e, f"bit-exact {_i(r.get(e + 'vectors', 'int'))}") + "; " + _caught(r, e))

    rows = [["design", *(f"{r.get('scope', 'str')}: {_design(r)}" for r in cols)],
            ["bit-exact", *(exact(r) for r in cols)],
            ["broken build (`-DHDRG_BREAK_ROUNDING`)", *(broken(r) for r in cols)],
            ["cycles / sample", *(cycles(r) for r in cols)],
            ["highest output rate", *(_rate(r) for r in cols)],
            ["firmware", *(firmware(r) for r in cols)],
            ["LUT / FF / DSP / BRAM", *(f"**{_resources(r)}**" for r in cols)],
            ["Fmax", *(_fmax(r) for r in cols)],
            ["the dedicated RTL's evaluator alone (`hdrg_eval_tm`)", *(alone(r) for r in cols)],
            ["tools", *("; ".join(str(v) for v in r.get("tools", "dict").values()) for r in cols)]]
    return _table(["", "iCE40 UP5K", "Xilinx 7-series"], rows)


def cost_goals(recs: dict) -> str:
    """docs/COST.md "Goals": each goal (cycles per sample, bytes of code, LUT4, SB_MAC16, EBR and SPRAM
    cells, Fmax in MHz) with the record's figure and met / missed."""
    m4, ice, xc7 = recs["cortex-m4"], recs["ice40"], recs["xc7"]
    lean_cyc = [("firmware entry point", m4.get("builds.lean.cycles_per_sample"))]
    spec_cyc = [("specialized", m4.get("builds.specialized.cycles_per_sample"))]
    code = [("firmware entry point", m4.get("builds.lean.code_bytes", "int"))]

    def verdicts(items, goal, fmt):
        met = [n for n, v in items if v <= goal]
        missed = [f"{n} ({fmt(v)})" for n, v in items if v > goal]
        return "; ".join(([f"met: {', '.join(met)}"] if met else [])
                         + ([f"missed: {', '.join(missed)}"] if missed else []))

    worst, sets, aux = _fpga_cycles(xc7)
    luts = ice.get("luts", "int")
    lcs = ice.get("pnr.utilisation.ICESTORM_LC", "list")[0]
    e = "evaluator_alone."
    fits = ice.get("pnr.fits", "bool")
    e_fmax = ice.get(e + "fmax_mhz", "num?")
    e_ok = (ice.get(e + "luts", "int") <= UP5K["luts"] and ice.get(e + "dsps", "int") <= UP5K["dsps"]
            and e_fmax is not None and e_fmax >= FMAX_GOAL_MHZ and ice.get(e + "cycles_per_sample", "int") <= CYCLES_GOAL)
    cells = [(k, name, ice.get(k, "int")) for k, name in (("dsps", "SB_MAC16"), ("brams", "EBR"), ("sprams", "SPRAM"))]
    soc_exact = ice.get("bit_exact", "bool")
    rows = [[f"Cortex-M4 firmware entry point (`hdrg_step_out`) <= {M4_CYCLES_GOAL} cycles per sample (e2e mean, "
             "nominal model)", ", ".join(f"{n} {_d(v)}" for n, v in lean_cyc),
             verdicts(lean_cyc, M4_CYCLES_GOAL, lambda v: f"{v / M4_CYCLES_GOAL:.2f}x")],
            [f"Cortex-M4 specialized to the default configuration <= {M4_SPECIALIZED_CYCLES_GOAL} cycles per sample",
             ", ".join(f"{n} {_d(v)}" for n, v in spec_cyc),
             verdicts(spec_cyc, M4_SPECIALIZED_CYCLES_GOAL, lambda v: f"{v / M4_SPECIALIZED_CYCLES_GOAL:.2f}x")],
            [f"Cortex-M4 firmware entry point <= {M4_CODE_GOAL // 1024} KiB per-sample code (-Os)",
             ", ".join(f"{n} {_i(v)} B" for n, v in code),
             verdicts(code, M4_CODE_GOAL, lambda v: f"{_i(v - M4_CODE_GOAL)} B over")],
            [f"iCE40 UP5K, whole pipeline placed and routed: <= {_i(UP5K['luts'])} LUT4 "
             f"(aim {_i(UP5K_LUT_AIM)})", f"{_i(luts)} LUT4; " + (f"placed and routed: {_i(lcs)} logic cells "
                                                                 "(LUT4 and flip-flop)" if fits else "not placed"),
             _judge(luts, UP5K["luts"]) + ("" if fits else "; does not place")
             + f"; aim: {_judge(luts, UP5K_LUT_AIM)} on LUT4, {_judge(lcs, UP5K_LUT_AIM)} on placed logic cells"],
            ["iCE40 UP5K, whole pipeline: within the UP5K's DSP, EBR and SPRAM",
             ", ".join(f"{_i(v)} {name} of {UP5K[k]}" for k, name, v in cells),
             _judge(max(v / UP5K[k] for k, _, v in cells), 1.0)],
            [f"iCE40 Fmax >= {FMAX_GOAL_MHZ:g} MHz", _fmax(ice, goal=False),
             _judge(ice.get("fmax_mhz"), FMAX_GOAL_MHZ, at_most=False) if fits else "not measurable: not placed"],
            ["iCE40 bit-exact on every vector under Icarus and Verilator",
             f"{_i(ice.get('vectors', 'int'))} vectors (Verilator), {_i(ice.get('icarus_vectors', 'int'))} (Icarus)",
             ("Verilator: met; Icarus: only the subset (every vector would take hours)" if soc_exact
              else "missed: a mismatch")],
            ["iCE40 cycles per sample and highest output rate stated", f"{_cycles_text(ice)}; {_rate(ice)}",
             "stated"],
            [f"dedicated RTL (`hdrg_top`, 7-series) <= {CYCLES_GOAL} cycles per sample (worst, Icarus)",
             f"{worst} ({', '.join(sets)}); {aux} (aux, up to 16 aux terms)",
             f"{_judge(worst, CYCLES_GOAL)} on {', '.join(sets)}; {_judge(aux, CYCLES_GOAL)} on aux"],
            ["the dedicated RTL's evaluator alone on the UP5K (LUT4, SB_MAC16, Fmax, cycles)",
             f"{_i(ice.get(e + 'luts', 'int'))} LUT4, {ice.get(e + 'dsps', 'int')} SB_MAC16, "
             f"{_mhz(ice, e + 'fmax_mhz')}, {ice.get(e + 'cycles_per_sample', 'int')} cycles",
             "met" if e_ok else "missed"]]
    return _table(["goal", "measured", "verdict"], rows)


# -- the registry, the markers, the documents ------------------------------------------------------------

# table -> (the targets whose records it reads, renderer)
TABLES = {
    "cortex-m4": (("cortex-m4",), readme_m4),
    "fpga": (("ice40", "xc7"), readme_fpga),
    "cortex-m4-measured": (("cortex-m4",), cost_m4),
    "cortex-m4-stages": (("cortex-m4",), cost_m4_stages),
    "cortex-m4-mix": (("cortex-m4",), cost_m4_mix),
    "fpga-measured": (("ice40", "xc7"), cost_fpga),
    "goals": (("cortex-m4", "ice40", "xc7"), cost_goals),
}


def commands(name: str) -> list:
    """The commands that measure the records of table ``name``."""
    return [command(t) for t in TABLES[name][0]]


def marker(name: str) -> str:
    """The opening marker of table ``name`` (its name and the commands of its records)."""
    return f"<!-- cost-table: {name} ({'; '.join(commands(name))}) -->"


def render(name: str, recs: dict) -> str:
    """The markdown of table ``name`` from ``recs`` (target -> Record)."""
    if name not in TABLES:
        raise RecordError(f"unknown cost table {name!r} (known: {', '.join(TABLES)})")
    missing = [t for t in TABLES[name][0] if t not in recs]
    if missing:
        raise RecordError(f"table {name} needs the record of {', '.join(missing)} ({'; '.join(map(command, missing))})")
    return TABLES[name][1](recs)


def renderable(recs: dict) -> list:
    """The tables whose records are all in ``recs``."""
    return [n for n, (targets, _) in TABLES.items() if all(t in recs for t in targets)]


def blocks(text: str, where: str = "the document") -> list:
    """The marked tables of a document: (name, marker line, table text, first and last line index of the
    table); a RecordError for an unknown name or a marker without its end."""
    lines, out, i = text.split("\n"), [], 0
    while i < len(lines):
        m = _OPEN.match(lines[i])
        if m is None:
            if lines[i].startswith("<!-- cost-table"):
                raise RecordError(f"{where}, line {i + 1}: a cost-table marker not of the form "
                                  f"'<!-- cost-table: NAME (COMMAND; ...) -->'")
            i += 1
            continue
        if m.group(1) not in TABLES:
            raise RecordError(f"{where}, line {i + 1}: unknown cost table {m.group(1)!r} (known: {', '.join(TABLES)})")
        j = next((k for k in range(i + 1, len(lines)) if lines[k] == END or lines[k].startswith("<!-- cost-table")),
                 len(lines))
        if j == len(lines) or lines[j] != END:
            raise RecordError(f"{where}, line {i + 1}: cost table {m.group(1)} has no {END} before "
                              + ("the end of the file" if j == len(lines) else f"the next marker (line {j + 1})"))
        out.append((m.group(1), lines[i], "\n".join(lines[i + 1:j]).strip("\n"), i, j))
        i = j + 1
    return out


def fill(text: str, recs: dict, where: str = "the document") -> str:
    """``text`` with every marked table (and its marker) rendered anew from ``recs``."""
    lines = text.split("\n")
    for name, _, _, i, j in reversed(blocks(text, where)):
        lines[i:j + 1] = [marker(name), render(name, recs), END]
    return "\n".join(lines)


def differences(text: str, recs: dict, where: str = "the document") -> list:
    """The tables of ``text`` that differ from what ``recs`` render: (name, what differs)."""
    out = []
    for name, head, body, _, _ in blocks(text, where):
        if head != marker(name):
            out.append((name, f"marker {head!r}, expected {marker(name)!r}"))
        want = render(name, recs)
        if body != want:
            diff = next((k for k, (a, b) in enumerate(zip(body.split("\n"), want.split("\n"))) if a != b),
                        min(len(body.split("\n")), len(want.split("\n"))))
            out.append((name, f"table line {diff + 1} differs from what the records render"))
    return out


def print_tables(recs: dict) -> str:
    """Every table ``recs`` can render, each between its markers (what `hdrg cost --tables` prints)."""
    names = renderable(recs)
    if not names:
        have = ", ".join(f"{t} ({r.path})" for t, r in recs.items())
        raise RecordError(f"no cost table reads only the records given ({have}); tables: "
                          + "; ".join(f"{n} needs {', '.join(t)}" for n, (t, _) in TABLES.items()))
    return "\n\n".join(f"{marker(n)}\n{render(n, recs)}\n{END}" for n in names) + "\n"
