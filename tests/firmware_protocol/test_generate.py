import os
import re
import shutil
import subprocess

import pytest

from firmware_protocol import REGISTER_MAP, Status
from firmware_protocol.generate import GENERATED_DIR, HEADER_NAME, artefacts, write_all


def test_committed_artefacts_are_not_stale():
    for name, text in artefacts().items():
        committed = (GENERATED_DIR / name).read_text()
        assert committed == text, f"{name} is stale: run python -m firmware_protocol.generate"


def test_markdown_lists_every_register():
    md = artefacts()["REGISTERS.md"]
    for reg in REGISTER_MAP:
        assert f"| {reg.name} |" in md


def _header_values(printed: dict[str, list[str]]) -> None:
    """Check the header's values, as a C program printed them or as read from its
    ``#define`` lines (name -> [address, words, scale, counts, access, mirror])."""
    from firmware_protocol import register
    from firmware_protocol.canopen import mirror_index

    for reg in REGISTER_MAP:
        addr, words, scale, counts, access, mirror = printed[reg.name]
        assert int(addr) == reg.offset and int(words) == reg.words
        assert float(scale) == pytest.approx(reg.scale) and int(counts) * reg.scale == pytest.approx(1.0)
        assert int(access) == (3 if reg.writable else 1) and int(mirror) == mirror_index(reg)
    for flag in Status:
        assert int(printed[f"STATUS_{flag.name}"][0]) == int(flag)
    assert int(printed["AXIS1_TARGET"][0]) == register("TARGET_ANGLE").address(1)


def _c_compiler() -> str | None:
    """``$CC``, else the first of gcc, cc and clang on PATH (None: no compiler)."""
    for name in (os.environ.get("CC"), "gcc", "cc", "clang"):
        if name and shutil.which(name):
            return name
    return None


@pytest.mark.skipif(
    _c_compiler() is None,
    reason="no C compiler ($CC, gcc, cc or clang): the header's values are checked from its text only",
)
def test_c_header_compiles_and_matches_python(tmp_path):
    write_all(tmp_path)
    lines = []
    for reg in REGISTER_MAP:
        kind = "OFS" if reg.per_axis else "ADDR"
        lines.append(
            f'printf("{reg.name} %d %d %.9g %d %u %u\\n", HT_{reg.name}_{kind}, '
            f"HT_{reg.name}_WORDS, (double)HT_{reg.name}_SCALE, HT_{reg.name}_COUNTS_PER_UNIT, "
            f"HT_{reg.name}_ACCESS, HT_{reg.name}_CO_MIRROR);"
        )
    for flag in Status:
        lines.append(f'printf("STATUS_{flag.name} %u\\n", HT_STATUS_{flag.name});')
    lines.append('printf("AXIS1_TARGET %d\\n", HT_AXIS_REG(1, HT_TARGET_ANGLE_OFS));')
    src = tmp_path / "main.c"
    body = "\n".join(lines)
    src.write_text(f'#include <stdio.h>\n#include "{HEADER_NAME}"\nint main(void){{\n{body}\nreturn 0;}}\n')
    exe = tmp_path / "main"
    cc = _c_compiler()
    assert cc is not None
    subprocess.run(
        [cc, "-std=c99", "-Wall", "-Werror", "-I", str(tmp_path), str(src), "-o", str(exe)], check=True
    )
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout
    _header_values({m[0]: m[1:] for m in (line.split() for line in out.splitlines())})


def test_c_header_defines_match_python():
    # without a compiler (make test needs only Python, pip and make) the values are still
    # checked: every object-like #define read as a literal or as another define's value
    text = artefacts()[HEADER_NAME]
    defines = dict(re.findall(r"^#define (HT_\w+) (\S+)$", text, re.M))

    def value(name: str) -> str:
        v = defines[name]
        return value(v) if v in defines else v.rstrip("u")

    got: dict[str, list[str]] = {}
    for reg in REGISTER_MAP:
        kind = "OFS" if reg.per_axis else "ADDR"
        fields = (kind, "WORDS", "SCALE", "COUNTS_PER_UNIT", "ACCESS", "CO_MIRROR")
        got[reg.name] = [
            str(int(v, 0)) if v[:2] == "0x" else v for v in (value(f"HT_{reg.name}_{f}") for f in fields)
        ]
    for flag in Status:
        got[f"STATUS_{flag.name}"] = [str(int(value(f"HT_STATUS_{flag.name}"), 0))]
    axis = int(value("HT_AXIS_BASE")) + int(value("HT_AXIS_STRIDE")) + int(value("HT_TARGET_ANGLE_OFS"))
    got["AXIS1_TARGET"] = [str(axis)]
    assert "#define HT_AXIS_REG(axis, offset) (HT_AXIS_BASE + (axis) * HT_AXIS_STRIDE + (offset))" in text
    _header_values(got)
