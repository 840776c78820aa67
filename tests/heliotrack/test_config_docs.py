"""docs/config.md is generated from the schema; it must not drift."""

from heliotrack.cli import main
from heliotrack.config_docs import DOCS_PATH, reference


def test_config_reference_is_up_to_date():
    assert DOCS_PATH.read_text() == reference(), "docs/config.md is stale: run `heliotrack config docs`"


def test_reference_documents_every_key_of_every_table():
    text = reference()
    for needle in (
        '`[[links]] kind = "canopen"`',
        "`bitrate`",
        "`[hil.drive]`",
        "`[camera]`",
        "`[sky]`",
        "`heartbeat_timeout_s`",
        "`3 x period_s, at least 5 (set it when that is over 6553)`",
        '| `parity` | string |  | `"N"` | "N", "E", "O" |',
    ):
        assert needle in text, needle


def test_config_validate_command(tmp_path, capsys):
    from tests.conftest import DEFAULT_CONFIG, REPO

    assert main(["config", "validate", "--scenario", str(DEFAULT_CONFIG)]) == 0
    assert "ok (1 link(s), 2 tracker(s))" in capsys.readouterr().out
    assert main(["config", "validate", str(DEFAULT_CONFIG)]) == 2  # [hil] in a plant file
    assert "hil: expected a plant file, with no [hil] table" in capsys.readouterr().err
    plant = tmp_path / "plant.toml"  # the simulator's devices in a plant file: what run says
    plant.write_text(DEFAULT_CONFIG.read_text().split("[hil]")[0])
    assert main(["config", "validate", str(plant)]) == 2
    assert "links[0].port: expected a real device for heliotrack run" in capsys.readouterr().err
    # a plant's real devices in a scenario: what simulate says (validate had said ok)
    assert main(["config", "validate", "--scenario", str(REPO / "config" / "plant-example.toml")]) == 2
    assert 'links[0].port: expected "hil" in a simulation' in capsys.readouterr().err


def test_a_choice_or_array_of_choices_names_its_choices(tmp_path, capsys):
    from tests.conftest import DEFAULT_CONFIG

    text = DEFAULT_CONFIG.read_text()
    assert '\nsky = "clear"' in text
    p = tmp_path / "s.toml"
    p.write_text(text.replace('\nsky = "clear"', '\nsky = "sunny"', 1))
    assert main(["config", "validate", "--scenario", str(p)]) == 2
    err = capsys.readouterr().err
    assert 'hil.sky: expected one of "clear", "overcast", "partly-cloudy" (or an array of them)' in err
