"""`hdrg cost`: what the fixed-point pipeline costs on the targets it is built for, measured by
building and running it (docs/COST.md).

* ``cortex-m4`` / ``cortex-m7``: the C twin (firmware_ref/c) cross-compiled with Debian's
  arm-none-eabi-gcc (``-mcpu=... -mthumb -mfloat-abi=soft``, -O2 and -Os) and newlib/rdimon
  semihosting (firmware_ref/c/arm: startup, linker script), run on QEMU (``mps2-an386``: M4,
  ``mps2-an500``: M7; ``-semihosting``: stdin/stdout/exit of the driver go to the host), so that
  ``hdrg vectors check-impl`` runs every vector set on the 32-bit target (``bit_exact``).  A build
  with ``-DHDRG_BREAK_ROUNDING`` must fail that check (``broken_build_caught``).
  Instructions per sample: QEMU executes one instruction per translation block (``-singlestep``)
  and logs every executed one (``-d exec,nochain``, filtered to the library, libgcc and the
  return site); a sample is the window from the entry of ``hdrg_step_aux`` to the return to the
  driver (callees and libgcc helpers included).  Cycles: a per-instruction model of the Cortex-M4
  TRM (r0p1, table 3-1) over that executed stream (host_tools.bench.cost_m4_model; nominal and low/high).
  Per stage: the same trace of the -O2 build, each address attributed by its inline chain
  (``addr2line -i``; the build has ``-g``) to the stage function it enters from hdrg_step_aux
  (``STAGES``; primitives and library helpers called as functions to the calling stage).
  Code bytes: ``code_bytes`` is the per-sample path at -Os (functions of the linked ELF reachable
  from ``hdrg_step_aux``, library helpers included), ``code_bytes_no_aux_gen`` the same of a
  ``-DHDRG_AUX_GEN=0`` build; per stage from ``nm`` of a ``-fno-inline`` object; stack: the worst
  path of GCC's call graph (``-fcallgraph-info=su``).
* ``host``: the same C twin with the host gcc, check-impl, and ns/sample of the driver's ``BENCH``.

Nothing is copied from a table: every figure comes from the build and the run of this call.
"""
from __future__ import annotations

import collections
import re
import subprocess
from pathlib import Path

from firmware_ref import vocabulary as VOC
from host_tools import vectors as V
from host_tools.bench import cost_soc
from host_tools.bench.cost_fpga import evaluator_line, measure_fpga, summary_lines
from host_tools.bench.cost_m4_model import M4_MODEL, cycles_m4, mix_summary
from host_tools.bench.cost_tools import CostError, need, run_tool, tool_version
from host_tools.golden.compensate import DEFAULT_COMBINER, DEFAULT_ORDER, DEFAULT_RATE
from host_tools.vectors.runner import requests

ROOT = Path(__file__).resolve().parent.parent.parent
C_DIR = ROOT / "firmware_ref" / "c"
ARM_DIR = C_DIR / "arm"
TARGETS = ("cortex-m4", "cortex-m7", "ice40", "xc7", "host")
AUX_TABLE_SETS = ("aux", "validity")   # vector sets with aux_gen 1 tables (a build without the generators refuses them)
NEWLIB_SPECS = Path("/usr/lib/arm-none-eabi/newlib/rdimon.specs")
MCU = {"cortex-m4": ("cortex-m4", "mps2-an386"), "cortex-m7": ("cortex-m7", "mps2-an500")}
ARM_FLAGS = ("-std=c99", "-mthumb", "-mfloat-abi=soft", "-Wall", "-Wextra", "-Werror",
             # Debian's arm-none-eabi-gcc finds its own freestanding stdint.h before newlib's, which
             # then lacks the PRId64 macros: put newlib's headers first
             "-isystem", "/usr/include/newlib",
             # debug info (not in text/data/bss, no effect on the code): the per-stage attribution of
             # the inlined build reads the inline chains of the executed addresses (addr2line -i)
             "-g")
STEP = "hdrg_step_aux"                  # the per-sample entry point
LEAN_STEP = "hdrg_step_out"             # the firmware entry point (outputs only; driver -DHDRG_DRIVER_LEAN)
CORE = "step_core"                      # the body both entry points inline (transparent in the inline chains)
TRACE_SAMPLES = 300                     # samples per traced case (the first ones: power-on, warm-up, reversals)
# function -> stage (the -fno-inline build); primitives are charged to the stage that calls them
STAGES = {
    "sequencer": ("timer_step", "next_state", "state_length"),
    "proxy": ("proxy_u", "pword", "s32"),
    "rate": ("rate_step", "hist_back", "rate_reset"),
    "combiner": ("comb_step", "comb_restart", "comb_commit"),
    "evaluator": ("hdrg_evaluate", "hdrg_evaluate_bank", "evaluate_k", "horner_row", "horner_step", "clamp_q30"),
    "aux": ("aux_step", "aux_norm", "hdrg_rhuw", "hdrg_sin_q30"),
    "step": ("hdrg_step_aux", "hdrg_step", "hdrg_step_out", "step_core"),
    "table parser": ("hdrg_table_parse", "check_fields", "parse_aux", "check_horner", "check_horner_bank",
                     "hdrg_crc32_words",
                     "hdrg_word_name", "hdrg_error_name", "hdrg_init", "hdrg_reset", "derive_bank"),
}
PRIMITIVES = ("hdrg_asr", "hdrg_rhu", "hdrg_mul_rhu", "hdrg_floor_div", "hdrg_div_round", "hdrg_div_round_scaled",
              "hdrg_clamp", "hdrg_sat_signed", "abs64", "I64", "asr64", "asr32", "rhu64", "rhu64b", "rhu32", "mulq30",
              "clamp_one", "clamp32_one", "nlz32", "divlu", "hdrg_udiv64", "floor_divmod", "div_round")
STAGE_OF = {f: s for s, fs in STAGES.items() for f in fs}
# the O fields the lean driver (-DHDRG_DRIVER_LEAN: hdrg_step_out) answers; the rest are 0
LEAN_FIELDS = ("acc", "cnt", "y", "out", "bias", "valid", "flags")
# the configuration-specialized build (hdrg_fw.h HDRG_FIX_*) the cost benchmark measures: DEFAULT_RATE's
# estimator (diff), reversal's DEFAULT_ORDER + DEFAULT_COMBINER, the freq proxy, no aux generators (`hdrg fit`
# chooses the rate estimator and aux terms per device); table field -> value, and the -D flags that fix them
SPECIAL = {"proxy_kind": VOC.PROXY_KINDS.index("freq"), "rate_est": VOC.ESTIMATORS.index(DEFAULT_RATE["estimator"]),
           "combiner": VOC.COMBINERS.index(DEFAULT_COMBINER), "order": VOC.ORDERS.index(DEFAULT_ORDER),
           "aux_gen": 0}
_FIX = {"proxy_kind": "HDRG_FIX_PROXY", "rate_est": "HDRG_FIX_EST", "combiner": "HDRG_FIX_COMB",
        "order": "HDRG_FIX_ORDER", "aux_gen": "HDRG_AUX_GEN"}
SPECIAL_DEFINES = tuple(f"{_FIX[k]}={v}" for k, v in SPECIAL.items())


# -- MCU: build ----------------------------------------------------------------------------------------

def build_mcu(target: str, opt: str, out: Path, defines=(), noinline: bool = False) -> dict:
    """Compile the library, the driver and the startup for ``target``, link with newlib/rdimon.
    Returns the paths: ``elf``, ``lib`` (hdrg_fw.o), ``ci`` (call graph with stack use), ``map``."""
    need("arm-none-eabi-gcc")
    if not NEWLIB_SPECS.is_file():
        raise CostError(f"{NEWLIB_SPECS} not found: install the Debian package libnewlib-arm-none-eabi "
                        f"(apt-get install -y libnewlib-arm-none-eabi)")
    cpu, _ = MCU[target]
    out.mkdir(parents=True, exist_ok=True)
    cc = ["arm-none-eabi-gcc", f"-mcpu={cpu}", opt, *ARM_FLAGS, *(f"-D{d}" for d in defines)]
    if noinline:
        cc.append("-fno-inline")
    lib, drv, start = out / "hdrg_fw.o", out / "hdrg_fw_main.o", out / "startup.o"
    run_tool(cc + ["-fcallgraph-info=su", "-c", C_DIR / "hdrg_fw.c", "-o", lib], cwd=out, what="arm-none-eabi-gcc")
    run_tool(cc + ["-c", C_DIR / "hdrg_fw_main.c", "-o", drv], what="arm-none-eabi-gcc")
    run_tool(cc + ["-c", ARM_DIR / "startup.c", "-o", start], what="arm-none-eabi-gcc")
    elf, mp = out / "hdrg_fw.elf", out / "hdrg_fw.map"
    run_tool(cc + ["--specs=rdimon.specs", "-nostartfiles", "-T", ARM_DIR / "link.ld", f"-Wl,-Map={mp}",
               lib, drv, start, "-o", elf], what="arm-none-eabi-gcc (link)")
    return {"elf": elf, "lib": lib, "ci": out / "hdrg_fw.ci", "map": mp}


def qemu_argv(target: str, elf: Path, extra=()) -> list:
    """The QEMU command line that runs the driver with stdin/stdout through semihosting."""
    return [need("qemu-system-arm"), "-M", MCU[target][1], "-nographic", "-monitor", "none", "-serial", "none",
            "-semihosting-config", "enable=on,target=native", *extra, "-kernel", str(elf)]


# -- MCU: sizes, call graph, stack ------------------------------------------------------------------------

def symbols(obj: Path) -> dict:
    """name -> (address, size in bytes) of the function symbols (Thumb bit cleared)."""
    out = {}
    for line in run_tool([need("arm-none-eabi-nm"), "-S", obj], what="nm").splitlines():
        p = line.split()
        if len(p) == 4 and p[2] in "tTwW":
            out[p[3]] = (int(p[0], 16) & ~1, int(p[1], 16))
    return out


def section_sizes(obj: Path) -> dict:
    """text, data, bss bytes of an object (arm-none-eabi-size, Berkeley format)."""
    line = run_tool([need("arm-none-eabi-size"), obj], what="size").splitlines()[1].split()
    return {"text": int(line[0]), "data": int(line[1]), "bss": int(line[2])}


def call_graph(ci: Path) -> tuple:
    """GCC's -fcallgraph-info=su file -> ({function: static stack bytes or None}, {function: set(callees)},
    [functions whose stack use is dynamic])."""
    stack, edges, dynamic = {}, collections.defaultdict(set), []
    for line in ci.read_text().splitlines():
        m = re.match(r'node: \{ title: "(?:[^"]*:)?([^":]+)" label: "([^"]*)"', line)
        if m:
            s = re.search(r"\\n(\d+) bytes \(([^)]*)\)", m.group(2))
            stack[m.group(1)] = int(s.group(1)) if s else None
            if s and "dynamic" in s.group(2):
                dynamic.append(m.group(1))
            continue
        m = re.match(r'edge: \{ sourcename: "(?:[^"]*:)?([^":]+)" targetname: "(?:[^"]*:)?([^":]+)"', line)
        if m:
            edges[m.group(1)].add(m.group(2))
    return stack, edges, dynamic


def reachable(edges: dict, root: str) -> set:
    seen, todo = set(), [root]
    while todo:
        f = todo.pop()
        if f not in seen:
            seen.add(f)
            todo.extend(edges.get(f, ()))
    return seen


def worst_stack(stack: dict, edges: dict, root: str) -> tuple:
    """(bytes, path) of the deepest call path from ``root``; functions outside the object (libgcc,
    memset) count 0 and are listed in the path with '?'."""
    def go(f, seen):
        own = stack.get(f)
        best = (0, [])
        for g in edges.get(f, ()):
            if g not in seen:
                best = max(best, go(g, seen | {g}), key=lambda x: (x[0], len(x[1])))
        return (own or 0) + best[0], [f if own is not None else f + "?"] + best[1]
    return go(root, {root})


def elf_functions(elf: Path) -> tuple:
    """From the linked ELF's disassembly: ({function: bytes}, {function: set of functions it branches
    or calls to}); a function spans from its label to the next one (libgcc's assembler helpers have no
    symbol size)."""
    starts, edges, cur = [], collections.defaultdict(set), None
    for line in run_tool([need("arm-none-eabi-objdump"), "-d", elf], what="objdump").splitlines():
        m = re.match(r"([0-9a-f]+) <([^>]+)>:$", line)
        if m:
            cur = m.group(2)
            starts.append((int(m.group(1), 16), cur))
            continue
        m = re.search(r"\t(b\S*|cbn?z)\s.*<([^>+]+)(\+0x[0-9a-f]+)?>", line)
        if m and cur and m.group(2) != cur:
            edges[cur].add(m.group(2))
    end = max(a + s for a, s in symbols(elf).values())
    sizes = {n: (starts[i + 1][0] if i + 1 < len(starts) else end) - a for i, (a, n) in enumerate(starts)}
    return sizes, edges


def mcu_sizes(b: dict, step: str = STEP) -> dict:
    """Code bytes of the library object and of the per-sample path (every function of the linked ELF
    reachable from hdrg_step_aux, libgcc helpers included); worst stack of a sample and of a table
    load (GCC's call graph and stack use; libgcc helpers are not in it)."""
    lib_syms = symbols(b["lib"])
    stack, edges, dynamic = call_graph(b["ci"])
    fsizes, fedges = elf_functions(b["elf"])
    step_code = {f: fsizes[f] for f in sorted(reachable(fedges, step))}
    s_bytes, s_path = worst_stack(stack, edges, step)
    p_bytes, p_path = worst_stack(stack, edges, "hdrg_init")
    return {"library": section_sizes(b["lib"]), "functions": {f: s for f, (_, s) in sorted(lib_syms.items())},
            "step_functions": step_code, "code_bytes": sum(step_code.values()),
            "stack_step_bytes": s_bytes, "stack_step_path": s_path, "stack_init_bytes": p_bytes,
            "stack_init_path": p_path, "stack_dynamic": dynamic}


# -- MCU: instruction trace and cycle model ------------------------------------------------------------

def disassembly(elf: Path) -> dict:
    """address -> (mnemonic, operands, size in bytes) of every instruction in the ELF."""
    out = {}
    for line in run_tool([need("arm-none-eabi-objdump"), "-d", elf], what="objdump").splitlines():
        m = re.match(r"\s*([0-9a-f]+):\t([0-9a-f ]+?)\s*\t(\S+)\s*(.*)$", line)
        if m:
            size = 2 * len(m.group(2).split())
            out[int(m.group(1), 16)] = (m.group(3), m.group(4), size)
    return out


def _text_ranges(b: dict, elf_syms: dict) -> list:
    """[lo, hi) of the code a sample may execute: the library's functions, libgcc and mem*."""
    lib = set(symbols(b["lib"]))
    ranges = [elf_syms[f] for f in lib if f in elf_syms]
    for line in b["map"].read_text().splitlines():
        m = re.match(r"\s*\.text\S*\s+0x([0-9a-f]+)\s+0x([0-9a-f]+)\s+\S*(libgcc\.a|lib_a-mem(set|cpy|move))", line)
        if m:
            ranges.append((int(m.group(1), 16), int(m.group(2), 16)))
    return [(a, a + s) for a, s in ranges if s]


def _merge(ranges):
    out = []
    for lo, hi in sorted(ranges):
        if out and lo <= out[-1][1]:
            out[-1][1] = max(out[-1][1], hi)
        else:
            out.append([lo, hi])
    return out


def case_requests(set_name: str, cases=None, n: int = TRACE_SAMPLES) -> str:
    """The protocol requests of the first ``n`` samples of each case (all cases by default) of a
    committed pipeline vector set."""
    manifest = V.read_manifest(V.DEFAULT_DIR)
    meta = manifest["sets"][set_name]
    vs = V.load_set(V.DEFAULT_DIR, set_name, meta)
    reqs = requests(vs, None)
    lines, k = [], 0
    for ci, case in enumerate(vs.cases):
        lo, hi = case["rows"]
        table_req = reqs[k]
        body = reqs[k + 1:k + 1 + hi - lo]
        k += 1 + hi - lo
        if cases is None or ci in cases:
            lines.append(table_req[0])
            lines.extend(r[0] for r in body[:n])
    return "\n".join(lines) + "\nQUIT\n"


def trace_samples(target: str, b: dict, requests: str, workdir: Path, step: str = STEP) -> list:
    """Run the driver on QEMU one instruction per block with the exec log; returns, per sample,
    the list of executed addresses from the entry of ``step`` to the return to the driver."""
    elf_syms = symbols(b["elf"])
    entry = elf_syms[step][0]
    dis = disassembly(b["elf"])
    rets = sorted(a + s for a, (mn, ops, s) in dis.items() if mn.startswith("bl") and f"<{step}>" in ops)
    ranges = _merge(_text_ranges(b, elf_syms) + [(r, r + 2) for r in rets])
    log = workdir / "exec.log"
    filt = ",".join(f"0x{lo:x}..0x{hi - 1:x}" for lo, hi in ranges)
    pr = subprocess.run(qemu_argv(target, b["elf"], ["-singlestep", "-d", "exec,nochain", "-D", str(log),
                                                     "-dfilter", filt]),
                        input=requests.encode(), capture_output=True, timeout=1200)
    if pr.returncode not in (0, 1) or b"ERR" in pr.stdout:
        raise CostError(f"traced run failed (status {pr.returncode}): {pr.stdout[-300:]!r} {pr.stderr[-300:]!r}")
    samples, cur = [], None
    retset = set(rets)
    with open(log) as fh:
        for line in fh:
            if not line.startswith("Trace"):
                continue
            pc = int(line.split("[", 1)[1].split("/", 2)[1], 16)
            if cur is None:
                if pc == entry:
                    cur = [pc]
            elif pc in retset:
                samples.append(cur)
                cur = None
            else:
                cur.append(pc)
    log.unlink()
    if not samples:
        raise CostError("the exec trace holds no sample (QEMU log format changed?)")
    return samples


def inline_chains(elf: Path, addrs) -> dict:
    """address -> [function, ...] of the inline chain at that address (innermost first), from
    ``addr2line -a -f -i`` on the ELF's debug info."""
    addrs = sorted(set(addrs))
    out = run_tool([need("arm-none-eabi-addr2line"), "-e", elf, "-a", "-f", "-i", *(hex(a) for a in addrs)],
               what="addr2line").splitlines()
    chains, cur = {}, None
    for line in out:
        if line.startswith("0x"):
            cur = chains.setdefault(int(line, 16), [])
        elif cur is not None and ":" not in line and line.strip() not in ("", "??"):
            cur.append(line.strip())
    return chains


def stage_counts_inline(samples: list, elf: Path, step: str = STEP) -> tuple:
    """(Counter, {address: stage or None}): instructions per stage of the production (inlined) build, summed over the samples: an address
    belongs to the function its inline chain enters from hdrg_step_aux (proxy_u, rate_step, ... inlined
    into it), or to the outermost function of the chain in a called function (hdrg_evaluate_bank);
    primitives inlined straight into hdrg_step_aux count as "step", primitives and libgcc helpers
    called as functions count to the stage that called them."""
    chains = inline_chains(elf, {pc for s in samples for pc in s})
    name_of = {}
    for a, ch in chains.items():
        ch = [f.split(".")[0] for f in ch if f.split(".")[0] != CORE]
        if step in ch:
            i = ch.index(step)
            f = ch[i - 1] if i > 0 else step
            name_of[a] = "step" if f in PRIMITIVES else STAGE_OF.get(f, f"other ({f})")
        else:
            f = ch[-1] if ch else "?"
            name_of[a] = None if (f in PRIMITIVES or f.startswith("__") or f in ("memset", "memcpy", "?")) \
                else STAGE_OF.get(f, f"other ({f})")
    counts = collections.Counter()
    for s in samples:
        for st, part in _stage_runs(s, name_of):
            counts[st] += len(part)
    return counts, name_of


def _stats(xs):
    xs = sorted(xs)
    return {"mean": round(sum(xs) / len(xs), 1), "median": xs[len(xs) // 2], "max": xs[-1], "min": xs[0]}


def _stage_runs(stream: list, stage_of_pc) -> list:
    """The executed stream cut into runs of one stage: [(stage, [pc, ...]), ...] (stage_of_pc as
    returned by stage_counts_inline's ``name_of``: None keeps the current stage)."""
    runs, stage = [], "step"
    for pc in stream:
        st = stage_of_pc.get(pc)
        if st is not None:
            stage = st
        if runs and runs[-1][0] == stage:
            runs[-1][1].append(pc)
        else:
            runs.append((stage, [pc]))
    return runs


def check_cases(argv, accepts: dict, fields=None, log=print) -> dict:
    """check-impl of what a build accepts: of every vector set, the cases whose table has the field
    values ``accepts`` (table field -> value; {}: every case) compared answer by answer (the O fields
    ``fields``, default all), and the other cases' tables must be refused (ERR to their TABLE request).
    The primitives set (no table) is compared whole."""
    manifest = V.read_manifest(V.DEFAULT_DIR)
    rep = {"sets": {}, "vectors": 0, "mismatches": 0, "tables_refused": 0, "refusals_missed": 0, "first": None}
    for name, meta in manifest["sets"].items():
        reqs = requests(V.load_set(V.DEFAULT_DIR, name, meta), fields)
        pr = subprocess.run(argv, input=("".join(r[0] + "\n" for r in reqs) + "QUIT\n").encode(),
                            capture_output=True, timeout=1200)
        got = pr.stdout.decode(errors="replace").splitlines()
        case, ok, rows, bad, refused = -1, True, 0, 0, 0
        for k, (line, exp, row, pos) in enumerate(reqs):
            ans = got[k].split() if k < len(got) else []
            if line.startswith("TABLE"):
                case += 1
                f = meta["tables"][meta["cases"][case]["table"]]["fields"]
                ok = all(f.get(key, 0) == v for key, v in accepts.items())
                if not ok:
                    refused += 1
                    rep["refusals_missed"] += ans[:1] != ["ERR"]
            if not ok:
                continue
            rows += row is not None
            if not (ans == exp if pos is None else len(ans) == len(exp) and all(ans[p] == exp[p] for p in pos)):
                bad += 1
                if rep["first"] is None:
                    rep["first"] = f"{name}, request {k}: {line[:120]}\n  expected {' '.join(exp)}\n  got {got[k:k + 1]}"
        rep["sets"][name] = {"vectors": rows, "mismatches": bad, "tables_refused": refused}
        rep["vectors"] += rows
        rep["mismatches"] += bad
        rep["tables_refused"] += refused
        if log is not None:
            log(f"{name}: {rows} vectors compared, {bad} mismatches, {refused} tables refused")
    return rep


def measure_build(target: str, work: Path, name: str, defines=(), accepts=None, log=print) -> dict:
    """A firmware build with the lean entry point hdrg_step_out (driver -DHDRG_DRIVER_LEAN) and ``defines``:
    at -O2 and -Os checked on every vector it accepts (``accepts``: table field -> value, as check_cases;
    the O fields LEAN_FIELDS), the others refused; the -O2 trace of the e2e cases it accepts; code bytes of
    the per-sample path (reachable from hdrg_step_out) at -Os; a -DHDRG_BREAK_ROUNDING build must fail."""
    accepts = accepts or {}
    e2e = V.read_manifest(V.DEFAULT_DIR)["sets"]["e2e"]
    cases = [i for i, c in enumerate(e2e["cases"])
             if all(e2e["tables"][c["table"]]["fields"].get(k, 0) == v for k, v in accepts.items())]
    res = {"build": name, "entry": LEAN_STEP, "defines": list(defines), "accepts": accepts, "fields": list(LEAN_FIELDS),
           "e2e_cases": [e2e["cases"][i]["name"] for i in cases]}
    defs = ("HDRG_DRIVER_LEAN", *defines)
    for opt in ("-O2", "-Os"):
        b = build_mcu(target, opt, work / f"{target}-{name}{opt}", defines=defs)
        rep = check_cases(qemu_argv(target, b["elf"]), accepts, LEAN_FIELDS, log=lambda s: log(f"  {name} {opt}: {s}"))
        sz = mcu_sizes(b, LEAN_STEP)
        res[opt] = {"bit_exact": rep["mismatches"] == 0 and rep["refusals_missed"] == 0, "check": rep,
                    "code_bytes": sz["code_bytes"], "step_functions": sz["step_functions"], "library": sz["library"],
                    "stack_step_bytes": sz["stack_step_bytes"]}
        if opt == "-O2":
            dis = disassembly(b["elf"])
            samples = trace_samples(target, b, case_requests("e2e", cases), work, step=LEAN_STEP)
            counts, stage_of_pc = stage_counts_inline(samples, b["elf"], LEAN_STEP)
            cyc_stage = collections.Counter()
            for s_ in samples:
                for st_, part in _stage_runs(s_, stage_of_pc):
                    cyc_stage[st_] += cycles_m4(part, dis, **M4_MODEL["nominal"])
            n = len(samples)
            cyc = {k: [cycles_m4(s_, dis, **m) for s_ in samples] for k, m in M4_MODEL.items()}
            res["per_sample"] = {"samples": n, "instructions": _stats([len(s_) for s_ in samples]),
                                 "cycles_m4_model": {k: _stats(v) for k, v in cyc.items()},
                                 "per_stage_instructions": {k: round(v / n, 1) for k, v in counts.most_common()},
                                 "per_stage_cycles": {k: round(v / n, 1) for k, v in cyc_stage.most_common()},
                                 **mix_summary(samples, dis, cyc["nominal"])}
    bad = build_mcu(target, "-O2", work / f"{target}-{name}-broken", defines=(*defs, "HDRG_BREAK_ROUNDING"))
    res["broken_build_caught"] = check_cases(qemu_argv(target, bad["elf"]), accepts, LEAN_FIELDS,
                                             log=lambda s: None)["mismatches"] > 0
    res.update({"bit_exact": res["-O2"]["bit_exact"] and res["-Os"]["bit_exact"],
                "vectors": res["-O2"]["check"]["vectors"],
                "cycles_per_sample": res["per_sample"]["cycles_m4_model"]["nominal"]["mean"],
                "instructions_per_sample": res["per_sample"]["instructions"]["mean"],
                "code_bytes": res["-Os"]["code_bytes"]})
    return res


def measure_mcu(target: str, work: Path, log=print) -> dict:
    """Build -O2, -Os, the -Os build without aux generators (-DHDRG_AUX_GEN=0), the broken build and a
    -fno-inline build (code bytes per stage); check-impl on QEMU; trace -O2 and -Os (per stage from the
    -O2 trace's inline chains)."""
    cpu, machine = MCU[target]
    res = {"target": target, "cpu": cpu, "machine": machine,
           "tools": {"gcc": tool_version("arm-none-eabi-gcc"), "qemu": tool_version("qemu-system-arm"),
                     "binutils": tool_version("arm-none-eabi-objdump")}}
    builds = {}
    for opt in ("-O2", "-Os"):
        builds[opt] = b = build_mcu(target, opt, work / f"{target}{opt}")
        rep = V.check_impl(qemu_argv(target, b["elf"]), log=lambda s: log(f"  {opt}: {s}"))
        sizes = mcu_sizes(b)
        res[opt] = {"bit_exact": rep["mismatches"] == 0, "vectors": sum(s["rows"] for s in rep["sets"].values()),
                    "first_mismatch": rep["first"], **sizes}
    # a firmware without the aux generators: bit-exact on every set without aux_gen 1 tables (the
    # aux set and the validity set, which has aux-table cases, hold them), and it must refuse the
    # aux set's tables (every aux request then mismatches)
    na = build_mcu(target, "-Os", work / f"{target}-Os-noaux", defines=("HDRG_AUX_GEN=0",))
    sets = [n for n in V.read_manifest(V.DEFAULT_DIR)["sets"] if n not in AUX_TABLE_SETS]
    rep = V.check_impl(qemu_argv(target, na["elf"]), names=sets, log=lambda s: log(f"  -Os AUX_GEN=0: {s}"))
    rep_aux = V.check_impl(qemu_argv(target, na["elf"]), names=["aux"], log=lambda s: None)
    sz = mcu_sizes(na)
    res["-Os-no-aux-gen"] = {"bit_exact": rep["mismatches"] == 0, "sets": sets,
                             "vectors": sum(s["rows"] for s in rep["sets"].values()),
                             "aux_tables_refused": rep_aux["sets"]["aux"]["mismatches"] == rep_aux["sets"]["aux"]["requests"],
                             "code_bytes": sz["code_bytes"], "step_functions": sz["step_functions"],
                             "library": sz["library"], "stack_step_bytes": sz["stack_step_bytes"]}
    bad = build_mcu(target, "-O2", work / f"{target}-broken", defines=("HDRG_BREAK_ROUNDING",))
    rep = V.check_impl(qemu_argv(target, bad["elf"]), names=["primitives"], log=lambda s: None)
    res["broken_build_caught"] = rep["mismatches"] > 0
    # instruction trace: e2e (17 terms, mode reversal, Z word) and the aux set's simulated case
    manifest = V.read_manifest(V.DEFAULT_DIR)
    aux_last = len(manifest["sets"]["aux"]["cases"]) - 1
    workloads = {"e2e": case_requests("e2e"), "aux-sim": case_requests("aux", [aux_last])}
    res["per_stage"] = {}
    for opt, b in builds.items():
        dis = disassembly(b["elf"])
        res[opt]["per_sample"] = {}
        for wname, reqs in workloads.items():
            samples = trace_samples(target, b, reqs, work)
            cyc = {k: _stats([cycles_m4(s, dis, **m) for s in samples]) for k, m in M4_MODEL.items()}
            res[opt]["per_sample"][wname] = {"samples": len(samples), "instructions": _stats([len(s) for s in samples]),
                                             "cycles_m4_model": cyc}
            if wname == "e2e":          # per case (the trace holds the first TRACE_SAMPLES of each, in order)
                pc, k = {}, 0
                for c in manifest["sets"]["e2e"]["cases"]:
                    part = samples[k:k + min(TRACE_SAMPLES, c["rows"][1] - c["rows"][0])]
                    k += len(part)
                    pc[c["name"]] = {"instructions": round(sum(map(len, part)) / len(part), 1), "cycles_nominal": round(
                        sum(cycles_m4(s_, dis, **M4_MODEL["nominal"]) for s_ in part) / len(part), 1)}
                res[opt]["per_sample"][wname]["per_case"] = pc
            if opt == "-O2":            # per stage: the same trace, each address by its inline chain
                counts, stage_of_pc = stage_counts_inline(samples, b["elf"])
                cyc_stage = collections.Counter()
                for s_ in samples:      # the nominal model over each stage's runs (branch joins approximate)
                    for st_, part in _stage_runs(s_, stage_of_pc):
                        cyc_stage[st_] += cycles_m4(part, dis, **M4_MODEL["nominal"])
                n = len(samples)
                res["per_stage"][wname] = {
                    "samples": n, "instructions_mean": {k: round(v / n, 1) for k, v in counts.most_common()},
                    "cycles_nominal_mean": {k: round(v / n, 1) for k, v in cyc_stage.most_common()},
                    "total_instructions_mean": round(sum(len(s_) for s_ in samples) / n, 1)}
    ni = build_mcu(target, "-O2", work / f"{target}-noinline", noinline=True)
    per_stage_code = collections.Counter()
    for f, (_, sz_) in symbols(ni["lib"]).items():
        f = f.split(".")[0]
        per_stage_code[STAGE_OF.get(f, "primitives" if f in PRIMITIVES else f"other ({f})")] += sz_
    res["code_bytes_per_stage_noinline"] = dict(per_stage_code.most_common())
    # the firmware entry point (outputs only), generic and specialized to the default configuration
    res["builds"] = {"lean": measure_build(target, work, "lean", log=log),
                     "specialized": measure_build(target, work, "specialized", SPECIAL_DEFINES, SPECIAL, log=log)}
    ps = res["-O2"]["per_sample"]["e2e"]
    res.update({"build": "generic (hdrg_step_aux, every table), e2e all cases",
                "bit_exact": res["-O2"]["bit_exact"] and res["-Os"]["bit_exact"]
                and all(b_["bit_exact"] for b_ in res["builds"].values()),
                "instructions_per_sample": ps["instructions"]["mean"],
                "cycles_per_sample": ps["cycles_m4_model"]["nominal"]["mean"],
                "code_bytes": res["-Os"]["code_bytes"], "code_bytes_O2": res["-O2"]["code_bytes"],
                "code_bytes_no_aux_gen": res["-Os-no-aux-gen"]["code_bytes"],
                "stack_bytes": res["-O2"]["stack_step_bytes"],
                "cycle_model": "Cortex-M4 TRM table 3-1 per-instruction model over the executed stream"
                               + (" (M7 is dual-issue: an upper bound there)" if target == "cortex-m7" else "")})
    return res


# -- host ----------------------------------------------------------------------------------------------

def measure_host(work: Path, log=print) -> dict:
    gcc = need("gcc")
    work.mkdir(parents=True, exist_ok=True)
    exe = work / "hdrg_fw"
    run_tool([gcc, "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-c", C_DIR / "hdrg_fw.c", "-o", work / "hdrg_fw.o"],
         what="gcc")
    run_tool([gcc, "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-o", exe, work / "hdrg_fw.o",
          C_DIR / "hdrg_fw_main.c"], what="gcc")
    rep = V.check_impl([str(exe)], log=lambda s: log(f"  {s}"))
    # BENCH on the e2e inputs (binary records), best of 5 passes
    reqs = [r for r in case_requests("e2e", n=10 ** 9).splitlines() if r.startswith(("S ", "TABLE"))]
    table = next(r for r in reqs if r.startswith("TABLE"))
    import numpy as np
    rows = np.array([[int(x) for x in r.split()[1:7]] for r in reqs if r.startswith("S ")][:2400], np.int64)
    data = (table + f"\nBENCH {len(rows)} 5\n").encode() + rows.astype("<i8").tobytes() + b"QUIT\n"
    out = subprocess.run([str(exe)], input=data, capture_output=True).stdout.decode().split()
    ns = int(out[out.index("BENCH") + 2]) / len(rows)
    return {"target": "host", "tools": {"gcc": tool_version("gcc")}, "bit_exact": rep["mismatches"] == 0,
            "vectors": sum(s["rows"] for s in rep["sets"].values()), "ns_per_sample": round(ns, 1),
            "cycles_per_sample": None, "code_bytes": section_sizes_host(work / "hdrg_fw.o")}


def section_sizes_host(obj: Path) -> int:
    line = run_tool(["size", obj], what="size").splitlines()[1].split()
    return int(line[0])


# -- CLI -----------------------------------------------------------------------------------------------

def measure(target: str, work: Path, log=print) -> dict:
    if target in MCU:
        return measure_mcu(target, work, log)
    if target == "host":
        return measure_host(work, log)
    if target == "ice40":
        return cost_soc.measure_soc(work, log)
    return measure_fpga(target, work, log)


def summary(r: dict) -> str:
    lines = [f"target {r['target']}: bit_exact {r['bit_exact']}" + (f" (figures below: {r['build']})" if "build" in r else "")]
    for k in ("cycles_per_sample", "instructions_per_sample", "code_bytes", "code_bytes_O2", "code_bytes_no_aux_gen",
              "stack_bytes",
              "ns_per_sample", "luts", "ffs", "dsps", "brams", "sprams", "fmax_mhz", "broken_build_caught"):
        if k in r:
            lines.append(f"  {k}: {r[k]}")
    if "firmware" in r and "evaluator_alone" in r:
        lines.extend(cost_soc.summary_lines(r) + [evaluator_line(r)])
    elif "evaluator_alone" in r:
        lines.extend(summary_lines(r))
    if "per_stage" in r:
        for w, d in r["per_stage"].items():
            lines.append(f"  per stage ({w}, -O2, mean of {d['samples']}): instructions "
                         + ", ".join(f"{k} {v}" for k, v in d["instructions_mean"].items()) + "; cycles (nominal) "
                         + ", ".join(f"{k} {v}" for k, v in d["cycles_nominal_mean"].items()))
        na = r["-Os-no-aux-gen"]
        lines.append(f"  -Os -DHDRG_AUX_GEN=0: per-sample code {na['code_bytes']} B, bit_exact {na['bit_exact']} "
                     f"({na['vectors']} vectors, aux tables refused: {na['aux_tables_refused']})")
        lines.append("  code bytes by stage (-O2 -fno-inline): "
                     + ", ".join(f"{k} {v}" for k, v in r["code_bytes_per_stage_noinline"].items()))
        for name, b_ in r.get("builds", {}).items():
            c = b_["per_sample"]["cycles_m4_model"]
            lines.append(f"  build {name} ({b_['entry']}; {' '.join('-D' + d for d in b_['defines']) or 'generic'}): "
                         f"bit_exact {b_['bit_exact']} ({b_['vectors']} vectors, {b_['-O2']['check']['tables_refused']} "
                         f"tables refused), broken build caught {b_['broken_build_caught']}; e2e {', '.join(b_['e2e_cases'])}: "
                         f"{b_['instructions_per_sample']} instructions, cycles nominal {b_['cycles_per_sample']} (low "
                         f"{c['low']['mean']}, high {c['high']['mean']}; max {c['nominal']['max']}); per-sample code "
                         f"-Os {b_['code_bytes']} B, -O2 {b_['-O2']['code_bytes']} B; per stage (cycles) "
                         + ", ".join(f"{k} {v}" for k, v in b_["per_sample"]["per_stage_cycles"].items()))
        for opt in ("-O2", "-Os"):
            o = r[opt]
            lines.append(f"  {opt}: library text/data/bss {o['library']}, per-sample code {o['code_bytes']} B, "
                         f"stack {o['stack_step_bytes']} B ({' > '.join(o['stack_step_path'])}), table load stack "
                         f"{o['stack_init_bytes']} B")
            for w, d in o["per_sample"].items():
                c = d["cycles_m4_model"]
                lines.append(f"    {w}: {d['samples']} samples, instructions {d['instructions']}, cycles nominal "
                             f"{c['nominal']['mean']} (low {c['low']['mean']}, high {c['high']['mean']}; max "
                             f"{c['nominal']['max']})")
                if "per_case" in d:
                    lines.append("      per case (instructions / cycles nominal): " + ", ".join(
                        f"{k} {v['instructions']} / {v['cycles_nominal']}" for k, v in d["per_case"].items()))
    lines.append("  tools: " + "; ".join(f"{k}: {v}" for k, v in r.get("tools", {}).items()))
    return "\n".join(lines)
