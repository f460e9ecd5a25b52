"""The README and docs/ as a newcomer meets them: short, runnable, quiet and current.

Every Python block of README.md and docs/*.md runs as written without a warning; the
README's blocks find what they say; the README's set-up commands are the ones CI runs;
and the user documents carry no commit hashes, issue numbers or times of day.
"""

import re
import shlex
import warnings
from pathlib import Path

import numpy as np
import pytest

from mmreg.metrics import objects_found

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
USER_DOCUMENTS = [README, *DOCS, ROOT / "CHANGELOG.md"]
SECTIONS = [
    "Install",
    "Quick start",
    "Your LiDAR sweeps",
    "Your LiDAR logs",
    "Your scene flow",
    "Formats and frames",
    "What you get",
    "How well it works",
    "Learn more",
    "Citing",
    "Licence",
]
# Words of hexadecimal digits that are names, not commits: Argoverse 2 log ids.
HEX_NAMES = {"7fab2350", "adcf7d18", "0c6e62d7", "03b13aa21f68"}


def python_blocks(path):
    return re.findall(r"```python\n(.*?)```", path.read_text(), re.S)


def sections(path):
    """The README's ``## `` sections: title -> text."""
    parts = re.split(r"^## (.+)$", path.read_text(), flags=re.M)
    return dict(zip(parts[1::2], parts[2::2], strict=True))


BLOCKS = [(path, i, code) for path in [README, *DOCS] for i, code in enumerate(python_blocks(path))]


def run_block(code, name):
    """Runs a block in a fresh namespace; the namespace and every warning it gave."""
    namespace = {}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        exec(compile(code, name, "exec"), namespace)
    return namespace, [f"{w.category.__name__}: {w.message}" for w in caught]


def test_readme_fits_in_two_screens_with_its_sections_in_order():
    assert len(README.read_text().splitlines()) <= 210  # about two screens
    assert list(sections(README)) == SECTIONS
    assert "docs/img/demo.png" in README.read_text()


@pytest.mark.parametrize(
    ("path", "index", "code"),
    BLOCKS,
    ids=[f"{p.relative_to(ROOT)}-{i}" for p, i, _ in BLOCKS],
)
def test_block_runs_as_written_without_warnings(path, index, code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a block that writes files writes them here
    _, caught = run_block(code, f"{path.name} block {index}")
    assert caught == []


def test_every_readme_section_with_code_is_covered():
    with_code = [title for title, text in sections(README).items() if "```python" in text]
    assert with_code == ["Quick start", "Your LiDAR sweeps", "Your LiDAR logs", "Your scene flow"]
    assert len(python_blocks(ROOT / "docs" / "python.md")) >= 3


def _readme_block(title):
    (code,) = re.findall(r"```python\n(.*?)```", sections(README)[title], re.S)
    namespace, _ = run_block(code, title)
    return namespace


def test_quick_start_recovers_the_objects():
    namespace = _readme_block("Quick start")
    est, scene = namespace["est"], namespace["scene"]
    assert est.n_clusters_ == scene.labels.max() + 1
    assert np.all(np.linalg.det(est.rotations_) > 0.999)


def test_lidar_sweeps_block_finds_the_moving_cars():
    namespace = _readme_block("Your LiDAR sweeps")
    est, scene = namespace["est"], namespace["scene"]
    cars = [k for k in range(1, scene.labels.max() + 1) if (scene.labels == k).any()]
    assert objects_found(scene.labels, est.labels_, objects=cars) == 1.0
    assert est.moving_.sum() == len(cars) and not est.moving_[est.static_cluster_]
    # The ground, rings of road included, is the static world's.
    assert np.all(est.labels_[est.ground_mask_] == est.static_cluster_)


def test_lidar_logs_block_tracks_the_moving_cars():
    namespace = _readme_block("Your LiDAR logs")
    est, log = namespace["est"], namespace["log"]
    found = 0
    for car in (k for k, kind in enumerate(log.kinds) if kind == "car"):
        frames = [k for k in range(len(log.frames)) if log.moving[k][log.labels[k] == car].any()]
        held = [est.labels_[k][log.labels[k] == car] for k in frames]
        majority = [int(np.bincount(h[h >= 0]).argmax()) for h in held if (h >= 0).any()]
        ids = {i for i in majority if i > 0}
        assert len(ids) <= 1  # one id over the whole log: no identity switch
        found += bool(ids)
    assert found >= 3
    # A cruising car's track has its speed (m/s) within 5 %.
    objects = log.objects.set_index(["frame", "id"])
    for track, rows in est.tracks_.groupby("track"):
        held = np.concatenate([log.labels[k][est.labels_[k] == track] for k in rows.frame])
        car = int(np.bincount(held).argmax())
        if objects.loc[(rows.frame.iloc[0], car), "motion"] == "cruising":
            true = np.median([objects.loc[(k, car), "speed"] for k in rows.frame])
            assert abs(rows.speed.median() - true) < 0.05 * true


def test_scene_flow_block_finds_the_moving_car_and_the_gross_errors():
    namespace = _readme_block("Your scene flow")
    est, scene = namespace["est"], namespace["scene"]
    truth = np.where(scene.outlier_mask, -1, scene.labels)
    moving = list(range(1, scene.labels.max() + 1))
    assert objects_found(truth, est.labels_, objects=moving) == 1.0
    flagged = est.outlier_mask_[scene.outlier_mask].mean()
    assert flagged > 0.9  # most gross flow errors are labelled -1


def _commands(text):
    """Shell commands of a bash text: one per line or per ``&&``, comments dropped."""
    commands = []
    for line in text.splitlines():
        line = line.split(" #")[0].strip()
        if line and not line.startswith("#"):
            commands += [" ".join(shlex.split(c)) for c in line.split("&&")]
    return commands


def test_install_commands_are_those_ci_runs():
    (install,) = re.findall(r"```bash\n(.*?)```", sections(README)["Install"], re.S)
    readme = _commands(install)
    assert readme[:2] == ["python3 -m venv .venv", "source .venv/bin/activate"]
    ci = _commands((ROOT / ".ci" / "run").read_text())
    for command in readme[2:]:  # install, demo, tests: CI runs each as written
        assert command in ci, command
    assert readme[2:] == ["bash scripts/install.sh", "mmreg demo", "python -m pytest -q"]


@pytest.mark.parametrize("path", USER_DOCUMENTS, ids=lambda p: p.name)
def test_user_documents_carry_no_history_markers(path):
    text = path.read_text()
    assert not re.findall(r"\bissues? \d+|#\d+\b", text, re.I), "issue numbers"
    assert not re.findall(r"\b\d{1,2}:\d{2}( ?UTC)?\b(?!\d)", text), "times of day"
    hex_words = set(re.findall(r"\b(?=[0-9a-f]*\d)(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b", text))
    assert hex_words <= HEX_NAMES, f"commit hashes: {sorted(hex_words - HEX_NAMES)}"
