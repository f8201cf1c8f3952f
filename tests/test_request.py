"""A command's request (simulator.commands._request.SceneRequest): the scene file read once,
the flags over it, the inputs and the output plan, frozen; built once per run of simulate,
energy and montecarlo and handed to the shared helpers in place of argparse's namespace."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from foundation import InputError
from patterns.library import library_path
from simulator.cli import build_parser, main
from simulator.commands._outputs import check_outputs, input_paths
from simulator.commands._request import SceneRequest
from simulator.commands._scene import scene_document_from_args, scene_from_args

PATTERN = str(library_path("square_200"))


def request_of(argv: list[str], outputs: tuple[str, ...] = ("json", "csv")) -> SceneRequest:
    return SceneRequest.from_args(build_parser().parse_args(argv), outputs)


def scene_file(tmp_path: Path) -> Path:
    toml = tmp_path / "s.toml"
    toml.write_text(
        f'pattern = "{PATTERN}"\nchip_size_um = [200, 200]\nresolution_um = 4\n'
        "[effects]\ntwist = false\n"
    )
    return toml


def test_the_request_holds_the_document_flags_inputs_and_outputs(tmp_path):
    toml = scene_file(tmp_path)
    out = str(tmp_path / "e.json")
    r = request_of(["energy", str(toml), "--resolution", "5", "--at", "0,0,0", "--json", out])
    assert r.scene_file == str(toml) and r.base == tmp_path
    assert r.document["chip_size_um"] == [200, 200]  # the file's, not changed by the flags
    assert r.document["resolution_um"] == 4
    assert r.overrides == {(None, "resolution_um"): 5.0}
    assert r.inputs == (toml, Path(PATTERN))
    assert r.outputs == (("--json", out), ("--csv", None)) and r.force is False
    assert r.output("--json") == out and r.output("--csv") is None


def test_the_request_is_frozen_and_equal_for_the_same_flags_and_file(tmp_path):
    toml = str(scene_file(tmp_path))
    argv = ["simulate", toml, "--volume", "3", "--start", "0,0,0", "--force"]
    a, b = request_of(argv), request_of(argv)
    assert a == b and a is not b and a.force and a.volume_given()
    assert a != request_of([*argv[:-1]])  # without --force
    assert a != request_of(["simulate", toml, "--volume", "4", "--start", "0,0,0", "--force"])
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.force = False  # type: ignore[misc]


def test_the_helpers_take_the_request(tmp_path):
    """The scene, its merged document, the inputs and the output checks come from the request
    alone, as they came from the namespace; the request's document is not changed."""
    toml = scene_file(tmp_path)
    argv = ["simulate", str(toml), "--resolution", "5", "--start", "0,0,0"]
    r = request_of(argv)
    before = dict(r.document)
    doc, base = scene_document_from_args(r)
    assert doc["resolution_um"] == 5.0 and base == tmp_path and r.document == before
    # the document given to from_args (read once by the command) makes the same scene document
    again = SceneRequest.from_args(build_parser().parse_args(argv), doc=r.document)
    assert doc == scene_document_from_args(again)[0]
    scene = scene_from_args(r, note_frame=False, warn=False)
    assert scene.um_per_px == 5.0
    assert input_paths(r) == list(r.inputs) == [toml, Path(PATTERN)]
    check_outputs(r)  # no output asked
    taken = request_of([*argv, "--json", str(toml)])
    with pytest.raises(InputError, match="--json"):
        check_outputs(taken)  # an output over an input is refused
    exists = tmp_path / "old.json"
    exists.write_text("{}")
    with pytest.raises(InputError, match="--force"):
        check_outputs(request_of([*argv, "--json", str(exists)]))
    check_outputs(request_of([*argv, "--json", str(exists), "--force"]))


@pytest.mark.parametrize(
    "command",
    [
        ["simulate", "--start", "12,0,0"],
        ["energy", "--at", "0,0,0"],
        ["montecarlo", "--random", "2", "--spread", "1,1,0"],
    ],
)
def test_each_command_builds_its_request_once(command, monkeypatch, capsys, tmp_path):
    """simulate, energy and montecarlo build one request per run and hand it, never the
    namespace, to the scene's, outputs' and droplet helpers (stopped at the scene here)."""
    import simulator.commands._request as request_module
    import simulator.commands._scene as scene_module

    built, given = [], []
    real = request_module.SceneRequest.from_args

    def from_args(*a, **k):
        built.append(real(*a, **k))
        return built[-1]

    def stop(request, *a, **k):
        given.append(request)
        raise InputError("stopped at the scene")

    monkeypatch.setattr(request_module.SceneRequest, "from_args", from_args)
    module = __import__(f"simulator.commands.{command[0]}", fromlist=["run"])
    monkeypatch.setattr(module, "scene_from_args", stop)
    assert scene_module.scene_from_args is not stop
    argv = [*command, "--pattern", PATTERN, "--chip-size", "200", "--resolution", "4"]
    assert main([*argv, "--no-twist", "--json", str(tmp_path / "o.json"), "--quiet"]) == 2
    assert "stopped at the scene" in capsys.readouterr().err
    assert len(built) == 1 and given == built
    assert built[0].output("--json") == str(tmp_path / "o.json")


def _record_requests(monkeypatch, module, name: str) -> tuple[list, list]:
    """``SceneRequest.from_args`` counted, and the helper ``name`` of ``module`` (the module
    the command imports it from) replaced by one that records what it is given and stops."""
    import simulator.commands._request as request_module

    built, given = [], []
    real = request_module.SceneRequest.from_args

    def from_args(*a, **k):
        built.append(real(*a, **k))
        return built[-1]

    def stop(request, *a, **k):
        given.append(request)
        raise InputError("stopped at the scene")

    monkeypatch.setattr(request_module.SceneRequest, "from_args", from_args)
    monkeypatch.setattr(module, name, stop)
    return built, given


@pytest.mark.parametrize("chip", [["--chip-size", "200"], []])
def test_evaluate_builds_its_request_once(chip, monkeypatch, capsys, tmp_path):
    """evaluate hands its one request to the scene (stopped there); without a chip, the chip
    from the pattern's bounding box is added to that request, not read from the namespace."""
    import simulator.commands.evaluate as evaluate

    built, given = _record_requests(monkeypatch, evaluate, "scene_from_args")
    argv = ["evaluate", PATTERN, *chip, "--resolution", "4", "--out", str(tmp_path / "o")]
    assert main([*argv, "--quiet"]) == 2
    assert "stopped at the scene" in capsys.readouterr().err
    assert len(built) == 1 and len(given) == 1 and type(given[0]) is SceneRequest
    assert given[0].inputs == built[0].inputs and set(given[0].inputs) == {Path(PATTERN)}
    if chip:
        assert given == built and given[0].overrides[(None, "chip_size_um")] == [200.0, 200.0]
    else:
        assert (None, "chip_size_um") not in built[0].overrides
        assert given[0].overrides[(None, "chip_size_um")][0] > 0


def test_calibrate_builds_its_request_once(monkeypatch, capsys, tmp_path):
    """calibrate reads its scene file once, into the request its merged document is made of."""
    import simulator.commands._scene as scene_module

    built, given = _record_requests(monkeypatch, scene_module, "scene_document_from_args")
    csv = tmp_path / "t.csv"
    csv.write_text("x_um,y_um,twist_deg,trials,aligned\n0,0,0,10,5\n")
    toml = scene_file(tmp_path)
    out = str(tmp_path / "o")
    assert main(["calibrate", str(csv), str(toml), "--fit", "volume_nl", "--out", out]) == 2
    assert "stopped at the scene" in capsys.readouterr().err
    assert len(built) == 1 and given == built and type(given[0]) is SceneRequest
    assert given[0].scene_file == str(toml) and given[0].document["resolution_um"] == 4


def test_liquid_window_builds_its_request_once(monkeypatch, capsys, tmp_path):
    """liquid window hands its one request to the scene (stopped there)."""
    import simulator.commands._scene as scene_module

    built, given = _record_requests(monkeypatch, scene_module, "scene_from_args")
    argv = ["liquid", "window", "--pattern", PATTERN, "--chip-size", "200", "--volume", "3"]
    assert main(argv) == 2
    assert "stopped at the scene" in capsys.readouterr().err
    assert len(built) == 1 and given == built and type(given[0]) is SceneRequest
    assert given[0].volume_given() and given[0].overrides[(None, "chip_size_um")] == [200.0, 200.0]
