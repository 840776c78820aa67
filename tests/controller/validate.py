"""``heliotrack config validate`` on a plant file written for a test."""

from heliotrack.cli import main


def validated(tmp_path, capsys, text: str) -> tuple[str, str]:
    """Write ``text`` as a plant file, validate it (it must pass) and return (stdout, stderr)."""
    plant = tmp_path / "plant.toml"
    plant.write_text(text)
    assert main(["config", "validate", str(plant)]) == 0
    out = capsys.readouterr()
    return out.out, out.err
