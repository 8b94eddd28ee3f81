"""The Cortex-M4 cycle model of `hdrg cost` (host_tools.bench.cost): cycles of an executed instruction
stream (a QEMU trace, one address per instruction, with the disassembly ``dis``: address ->
(mnemonic, operands, size in bytes)) by the per-instruction table of the Cortex-M4 TRM, the
instruction mix and the fetches that flash wait states would add to."""
from __future__ import annotations

import collections
import re

# Cortex-M4 TRM r0p1 table 3-1 (cycles; P = pipeline refill of a taken branch, 1..3; N = registers)
M4_MODEL = {"nominal": {"P": 2, "div": 7}, "low": {"P": 1, "div": 2}, "high": {"P": 3, "div": 12}}
_LOADS = re.compile(r"^(ldr|str)(b|h|sb|sh|ex|exb|exh)?(\.w|\.n)?$")


def decode(stream: list, dis: dict):
    """Per executed instruction of ``stream``: (kind, base mnemonic, operands, taken), kind one of
    'divide', 'load/store' (a single LDR/STR), 'load/store pair' (LDRD/STRD), 'load/store multiple'
    (LDM/STM/PUSH/POP), 'table branch' (TBB/TBH), 'branch' (B*, CBZ/CBNZ), 'multiply' (MUL/MLA/MLS and
    the 32x32->64 SMULL/UMULL/SMLAL/UMLAL...), 'alu'; ``taken``: the next address is not this one +
    its size (the last instruction: not taken)."""
    for i, pc in enumerate(stream):
        mn, ops, size = dis[pc]
        base = mn.split(".")[0]
        nxt = stream[i + 1] if i + 1 < len(stream) else None
        taken = nxt is not None and nxt != pc + size
        if base in ("sdiv", "udiv"):
            kind = "divide"
        elif _LOADS.match(mn):
            kind = "load/store"
        elif base in ("ldrd", "strd"):
            kind = "load/store pair"
        elif base.startswith(("ldm", "stm", "push", "pop")):
            kind = "load/store multiple"
        elif base in ("tbb", "tbh"):
            kind = "table branch"
        elif base.startswith("b") and base not in ("bic", "bics", "bfi", "bfc") or base in ("cbz", "cbnz"):
            kind = "branch"
        elif base.startswith(_MULTIPLIES):
            kind = "multiply"
        else:
            kind = "alu"
        yield kind, base, ops, taken


_MULTIPLIES = ("mul", "mla", "mls", "smull", "umull", "smlal", "umlal", "smla", "smul", "smmul", "smmla")


def _registers(ops: str) -> str:
    """The register list ``{...}`` of an LDM/STM/PUSH/POP's operands ('' when it has none)."""
    return ops[ops.find("{") + 1:ops.find("}")] if "{" in ops else ""


def cycles_m4(stream: list, dis: dict, P: int, div: int) -> int:
    """Cycles of an executed instruction stream on the Cortex-M4 model: data processing, multiply
    (incl. 32x32->64 UMULL/SMLAL...) and a not-taken branch 1; DIV ``div``; single LDR/STR 2, or 1 right
    after another single load/store (pipelined); LDRD/STRD 3; LDM/STM/PUSH/POP 1 + N (+P with pc);
    a taken branch (next address != this + size), BL, BX, TBB/TBH 1 + P (TB 2 + P)."""
    total, prev_ls = 0, False
    for kind, base, ops, taken in decode(stream, dis):
        if kind == "divide":
            c = div
        elif kind == "load/store":
            c = (1 if prev_ls else 2) + (P if "pc" in ops.split(",")[0] else 0)
        elif kind == "load/store pair":
            c = 3
        elif kind == "load/store multiple":
            regs = _registers(ops)
            n = sum((int(b.split("-")[1][1:]) - int(b.split("-")[0][1:]) + 1) if "-" in b and b.strip()[0] == "r"
                    else 1 for b in regs.split(","))
            c = 1 + n + (P if "pc" in regs else 0)
        elif kind == "table branch":
            c = 2 + P
        elif kind == "branch":
            c = 1 + P if (taken or base in ("bl", "blx", "bx")) else 1
        else:
            c = 1
        prev_ls = kind == "load/store"
        total += c
    return total


MIX_CLASSES = ("alu", "multiply", "divide", "load/store", "load/store multiple", "branch taken", "branch not taken")
FLASH_WAIT_STATES = (1, 2, 5)   # wait states of on-chip flash (e.g. STM32F4 at 168 MHz: 5)


def instruction_mix(stream: list, dis: dict) -> tuple[dict, int]:
    """({class: count}, flash fetch events) of an executed instruction stream (:func:`decode`): the
    classes of MIX_CLASSES (load/store multiple: LDM/STM/PUSH/POP/LDRD/STRD; a table branch is a
    branch), and the events that would miss a flash prefetch buffer with no cache: every taken branch
    and every POP/LDM/LDR into pc (a refetch at a new address) and every literal-pool load (LDR ...,
    [pc, ...]).  The per-instruction model (:func:`cycles_m4`) assumes zero-wait-state memory; with
    code in flash of W wait states and no cache each event costs up to W more cycles."""
    mix = dict.fromkeys(MIX_CLASSES, 0)
    events = 0
    for kind, base, ops, taken in decode(stream, dis):
        if kind in ("load/store pair", "load/store multiple"):
            k = "load/store multiple"
            events += "pc" in _registers(ops)
        elif kind == "load/store":
            k = "load/store"
            events += "[pc" in ops or "pc" in ops.split(",")[0]     # a literal-pool load, or a load into pc
        elif kind in ("branch", "table branch"):
            taken = taken or base in ("bl", "blx", "bx")
            k = "branch taken" if taken else "branch not taken"
            events += taken
        else:
            k = kind
        mix[k] += 1
    return mix, events


def mix_summary(samples: list, dis: dict, nominal_cycles: list) -> dict:
    """Per-sample means over traced ``samples``: instruction mix (:func:`instruction_mix`), flash
    fetch events and the nominal cycles (``nominal_cycles``: :func:`cycles_m4` of each sample, nominal
    model) with code in flash of each of FLASH_WAIT_STATES wait states and no cache (each event + W:
    an upper bound; a flash accelerator or a cache hides most of it)."""
    n = max(len(samples), 1)
    tot = collections.Counter()
    events = 0
    for s_ in samples:
        m, e = instruction_mix(s_, dis)
        tot.update(m)
        events += e
    nominal = sum(nominal_cycles) / n
    return {"mix": {k: round(tot[k] / n, 1) for k in MIX_CLASSES}, "flash_events": round(events / n, 1),
            "cycles_flash_no_cache": {str(w): round(nominal + w * events / n, 1) for w in FLASH_WAIT_STATES}}
