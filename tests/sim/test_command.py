"""``routing-svc cosim`` through its argparse entry points."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from routing_svc.sim import command


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="routing-svc")
    command.add_parser(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(["cosim", *argv])


def test_cosim_command_prints_a_summary_and_writes_plots(
    grid_net: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    args = _parse(
        [
            "--net", str(grid_net), "--vehicles", "3", "--duration", "600", "--warmup", "60",
            "--drain", "240", "--rate", "60", "--density", "15", "--policies", "sa,sumo-stop",
            "--seeds", "5", "--workers", "1", "--out", str(out), "--quiet",
        ]
    )  # fmt: skip
    assert args.run(args) == 0
    captured = capsys.readouterr()
    printed = json.loads(captured.out)
    assert set(printed["policies"]) == {"sa", "sumo-stop"}
    assert printed["signals"]["signals"] == 0  # the grid has no traffic lights
    assert "never turn green" not in captured.err
    assert printed["policies"]["sa"]["served"] >= 1
    assert json.loads((out / "summary.json").read_text())["policies"].keys() == {"sa", "sumo-stop"}
    for name in ("waits", "positions", "objective"):
        assert (out / f"cosim-{name}.png").stat().st_size > 1000


def test_cosim_command_warns_of_lights_that_never_turn_green(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from routing_svc.network import load_network
    from routing_svc.network.catalogue import resolve_network
    from routing_svc.network.signals import audit_signals

    out = tmp_path / "out"
    args = _parse(
        [
            "--net", "bs3d", "--vehicles", "3", "--duration", "600", "--warmup", "60",
            "--drain", "240", "--rate", "60", "--density", "3", "--policies", "sumo-stop",
            "--seeds", "0", "--workers", "1", "--out", str(out), "--quiet",
        ]
    )  # fmt: skip
    assert args.run(args) == 0
    captured = capsys.readouterr()
    net = resolve_network("bs3d")
    audit = audit_signals(net, load_network(net))
    assert audit.never_green  # the game's light is made to be switched by hand
    assert json.loads(captured.out)["signals"] == audit.to_dict()
    assert json.loads((out / "summary.json").read_text())["signals"] == audit.to_dict()
    assert f"{len(audit.never_green)} of the {audit.links} signalled links of bs3d" in captured.err
    assert "--tls.rebuild" in captured.err


def test_cosim_command_rejects_unknown_policies(grid_net: Path, tmp_path: Path) -> None:
    from routing_svc.errors import InvalidInput

    args = _parse(["--net", str(grid_net), "--policies", "sa,teleport", "--out", str(tmp_path)])
    with pytest.raises(InvalidInput, match="teleport"):
        args.run(args)


def test_bad_seeds_are_an_argparse_error() -> None:
    with pytest.raises(SystemExit):
        _parse(["--seeds", "a,b"])


def test_an_incident_sample_below_one_is_refused_before_anything_runs(
    grid_net: Path, tmp_path: Path
) -> None:
    from routing_svc.errors import InvalidInput

    out = tmp_path / "out"
    args = _parse(
        ["--net", str(grid_net), "--mode", "incidents", "--incident-sample", "0", "--out", str(out)]
    )
    with pytest.raises(InvalidInput, match="incident_sample"):
        args.run(args)
    assert not out.exists()


def test_the_queue_order_is_an_option_and_a_bad_one_is_refused(
    grid_net: Path, tmp_path: Path
) -> None:
    from routing_svc.errors import InvalidInput
    from routing_svc.sim.spec import CosimSpec

    assert _parse(["--net", str(grid_net)]).queue == "soonest"
    assert _parse(["--net", str(grid_net), "--queue", "fifo"]).queue == "fifo"
    with pytest.raises(SystemExit):
        _parse(["--net", str(grid_net), "--queue", "random"])
    with pytest.raises(InvalidInput, match="queue_order"):
        CosimSpec(network=str(grid_net), queue_order="random")
    assert CosimSpec(network=str(grid_net)).to_dict()["queue_order"] == "soonest"
