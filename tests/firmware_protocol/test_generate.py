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
    subprocess.run(
        ["gcc", "-std=c99", "-Wall", "-Werror", "-I", str(tmp_path), str(src), "-o", str(exe)], check=True
    )
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout
    got = {m[0]: m[1:] for m in (line.split() for line in out.splitlines())}
    from firmware_protocol.canopen import mirror_index

    for reg in REGISTER_MAP:
        addr, words, scale, counts, access, mirror = got[reg.name]
        assert int(addr) == reg.offset and int(words) == reg.words
        assert float(scale) == pytest.approx(reg.scale) and int(counts) * reg.scale == pytest.approx(1.0)
        assert int(access) == (3 if reg.writable else 1) and int(mirror) == mirror_index(reg)
    for flag in Status:
        assert int(got[f"STATUS_{flag.name}"][0]) == int(flag)
    from firmware_protocol import register

    assert int(got["AXIS1_TARGET"][0]) == register("TARGET_ANGLE").address(1)
