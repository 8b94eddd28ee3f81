"""The tool helpers of `hdrg cost` shared by the MCU (host_tools.bench.cost) and the FPGA/RTL measurements
(host_tools.bench.cost_fpga, cost_rtl, cost_aux, cost_soc): find a tool or name the Debian package that ships it,
its version banner, run it or raise a CostError with its output."""
from __future__ import annotations

import shutil
import subprocess

# tool -> the Debian package that ships it
PACKAGES = {"arm-none-eabi-gcc": "gcc-arm-none-eabi", "arm-none-eabi-nm": "binutils-arm-none-eabi",
            "arm-none-eabi-objdump": "binutils-arm-none-eabi", "arm-none-eabi-size": "binutils-arm-none-eabi",
            "arm-none-eabi-addr2line": "binutils-arm-none-eabi",
            "qemu-system-arm": "qemu-system-arm", "gcc": "gcc", "yosys": "yosys", "nextpnr-ice40": "nextpnr-ice40",
            "iverilog": "iverilog", "vvp": "iverilog", "verilator": "verilator",
            "riscv64-unknown-elf-gcc": "gcc-riscv64-unknown-elf", "riscv64-unknown-elf-objcopy": "binutils-riscv64-unknown-elf",
            "riscv64-unknown-elf-nm": "binutils-riscv64-unknown-elf"}


class CostError(ValueError):
    """A target that cannot be measured: a missing tool, a failed build or run."""


def need(tool: str) -> str:
    """The path of ``tool`` or a CostError naming the Debian package to install."""
    path = shutil.which(tool)
    if path is None:
        pkg = PACKAGES.get(tool, tool)
        raise CostError(f"{tool} not found: install the Debian package {pkg} (apt-get install -y {pkg})")
    return path


def tool_version(tool: str, arg: str = "--version") -> str:
    """The first line of ``tool arg`` (the version banner), '?' when it prints nothing."""
    pr = subprocess.run([need(tool), arg], capture_output=True, text=True)
    text = (pr.stdout or pr.stderr).strip().splitlines()
    return text[0].strip() if text else "?"


def run_tool(argv, cwd=None, what="command", **kw) -> str:
    """Run ``argv`` (in ``cwd``); its stdout, or a CostError naming ``what`` with the tail of its output."""
    pr = subprocess.run([str(a) for a in argv], cwd=cwd, capture_output=True, text=True, **kw)
    if pr.returncode != 0:
        raise CostError(f"{what} failed ({' '.join(map(str, argv))[:300]}):\n{(pr.stderr or pr.stdout)[-2000:]}")
    return pr.stdout
