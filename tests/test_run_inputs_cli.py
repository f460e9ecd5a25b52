"""Small traps of the command line around its inputs: the order of evaluate's arguments,
messages that name Python parameters instead of options, grammar."""

import numpy as np
import pytest

from mmreg.cli import main


def _write_pairs(folder):
    """Two files of correspondences: a block at rest and a box moving 0.5 m along x."""
    rng = np.random.default_rng(0)
    block = rng.uniform([0, 0, 0], [2, 2, 2], (150, 3))
    box = rng.uniform([6, 0, 0], [7, 1, 1], (80, 3))
    a = np.vstack([block, box])
    folder.mkdir()
    for k in range(2):
        np.save(
            folder / f"pair{k}.npy",
            np.hstack([a, a + np.r_[np.zeros((150, 3)), [[0.5, 0, 0]] * 80]]),
        )
    labels = np.r_[np.zeros(150, int), np.ones(80, int)]
    np.save(folder.parent / "truth.npy", labels)
    return folder


def test_evaluate_takes_job_between_run_and_truth(tmp_path, scheduler, capsys):
    data = _write_pairs(tmp_path / "pairs")
    out = tmp_path / "out"
    command = ["run", str(data), "--out", str(out), "--tau", "1", "--scheduler", scheduler, "-q"]
    assert main(command) == 0
    truth = str(tmp_path / "truth.npy")
    capsys.readouterr()
    assert main(["evaluate", str(out), truth, "--job", "pair1"]) == 0
    after = capsys.readouterr().out
    assert main(["evaluate", str(out), "--job", "pair1", truth]) == 0
    assert capsys.readouterr().out == after and "1.000" in after
    assert main(["evaluate", "--job", "pair1", str(out), truth, "--json"]) == 0
    assert '"iou": 1.0' in capsys.readouterr().out


def test_messages_name_options_not_parameters(tmp_path, capsys):
    from mmreg._cli._lidar_input import cli_words

    assert cli_words("choose one with pattern='*.bin' (--pattern '*.bin').") == (
        "choose one with --pattern '*.bin'."
    )
    assert cli_words("choose one with --topic (topic=).") == "choose one with --topic."
    assert cli_words("topic= (--topic) applies to a ROS bag only.") == (
        "--topic applies to a ROS bag only."
    )
    np.save(tmp_path / "a.npy", np.zeros((10, 6)))
    for option in (["--frame", "1"], ["--pattern", "*.bin"]):
        assert main(["register", str(tmp_path / "a.npy"), *option, "-q"]) == 2
        assert f"{option[0]} applies only to" in capsys.readouterr().err


def test_a_bag_of_several_topics_names_the_option(tmp_path, scheduler, capsys):
    pytest.importorskip("rosbags")
    from test_sequences import write_bag

    scans = [np.random.default_rng(k).uniform(-5, 5, (50, 3)) for k in range(2)]
    bag = write_bag(tmp_path / "drive", scans, topics=("/a", "/b"))
    for command in (
        ["register", str(bag), "-q", "--out", str(tmp_path / "r")],
        ["run", str(bag), "-q", "--out", str(tmp_path / "o"), "--scheduler", scheduler],
    ):
        assert main(command) == 2
        error = capsys.readouterr().err
        assert "choose one with --topic" in error and "topic=" not in error
