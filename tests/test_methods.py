"""The registry of methods: built-ins, run-time registration and entry-point plugins."""

import importlib
import sys
import textwrap

import numpy as np
import pytest
from sklearn.base import clone

from mmreg import MultiModelRegistration, NaiveRegistration, SequentialRANSAC, TLinkage
from mmreg.datasets import make_scene
from mmreg.methods import (
    BUILTIN_METHODS,
    ENTRY_POINT_GROUP,
    available_methods,
    make_method,
    method_parameters,
    register_method,
    unregister_method,
)

BUILTINS = ["naive", "sequential_ransac", "t_linkage", "ours_vanilla", "ours", "mmreg"]


def install_plugin(tmp_path, monkeypatch, module, source, entries):
    """A real installed distribution: ``toy-0.0.dist-info`` with entry points, on sys.path."""
    (tmp_path / f"{module}.py").write_text(textwrap.dedent(source))
    info = tmp_path / f"{module}-0.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module}\nVersion: 0.0\n")
    lines = "\n".join(f"{name} = {target}" for name, target in entries.items())
    (info / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\n{lines}\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.invalidate_caches()
    monkeypatch.delitem(sys.modules, module, raising=False)


TOY = """
from mmreg import NaiveRegistration

CALLS = []


def make(*, init="euclidean", random_state=None):
    CALLS.append(1)
    return NaiveRegistration(init=init, random_state=random_state)


class ToyRegistration(NaiveRegistration):
    pass


NOT_CALLABLE = 3
"""


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    install_plugin(
        tmp_path,
        monkeypatch,
        "toy_methods_plugin",
        TOY,
        {
            "toy": "toy_methods_plugin:make",
            "toy_class": "toy_methods_plugin:ToyRegistration",
            "toy_broken": "toy_methods_plugin_missing:make",
            "toy_value": "toy_methods_plugin:NOT_CALLABLE",
        },
    )


def test_builtins_are_listed_first_in_the_papers_order():
    assert list(BUILTIN_METHODS) == BUILTINS
    assert available_methods()[: len(BUILTINS)] == BUILTINS


@pytest.mark.parametrize("name", BUILTINS)
def test_make_method_gives_unfitted_cloneable_estimators(name):
    estimator = make_method(name)
    twin = clone(estimator)
    assert twin.get_params() == estimator.get_params()
    assert not hasattr(estimator, "labels_")
    assert make_method(name) is not estimator  # a new one every time


def test_builtins_are_the_papers_methods():
    assert type(make_method("naive")) is NaiveRegistration
    assert type(make_method("sequential_ransac")) is SequentialRANSAC
    assert type(make_method("t_linkage")) is TLinkage
    vanilla, ours, robust = make_method("ours_vanilla"), make_method("ours"), make_method("mmreg")
    assert isinstance(vanilla, MultiModelRegistration)
    assert (vanilla.variant, vanilla.tau) == ("paper", None)
    assert (ours.variant, ours.tau) == ("paper", 1.5)
    assert robust.get_params() == MultiModelRegistration().get_params()


def test_parameters_reach_the_estimator():
    est = make_method("ours", tau=5.0, min_cluster_size=3, max_iter=7, random_state=1)
    assert (est.tau, est.min_cluster_size, est.max_iter, est.random_state) == (5.0, 3, 7, 1)
    ransac = make_method("sequential_ransac", residual_threshold=0.01, max_trials=1000)
    assert (ransac.residual_threshold, ransac.max_trials) == (0.01, 1000)


def test_unknown_name_lists_the_available_methods():
    with pytest.raises(ValueError, match="Unknown method 'nope'") as info:
        make_method("nope")
    for name in BUILTINS:
        assert name in str(info.value)


def test_unknown_parameter_raises_unless_not_strict():
    with pytest.raises(TypeError, match="takes: .*init"):
        make_method("naive", tau=1.5)
    with pytest.raises(TypeError):
        make_method("ours_vanilla", tau=1.5)  # Vanilla is Ours without the gate
    assert make_method("naive", tau=1.5, strict=False).get_params() == (
        NaiveRegistration().get_params()
    )
    assert make_method("ours_vanilla", tau=1.5, strict=False).tau is None


def test_method_parameters():
    assert "tau" not in method_parameters("ours_vanilla")
    assert {"tau", "init", "random_state"} <= method_parameters("ours")
    assert method_parameters("mmreg") == frozenset(MultiModelRegistration().get_params())


def test_register_and_unregister(monkeypatch):
    def wide_gate(**params):
        return MultiModelRegistration(tau=10.0, **params)

    assert register_method("wide_gate", wide_gate) is wide_gate
    try:
        assert "wide_gate" in available_methods()
        assert make_method("wide_gate", max_iter=3).get_params()["tau"] == 10.0
        assert "max_iter" in method_parameters("wide_gate")  # from the estimator it builds
        with pytest.raises(ValueError, match="exists already"):
            register_method("wide_gate", wide_gate)
        with pytest.raises(ValueError, match="exists already"):
            register_method("ours", wide_gate)
    finally:
        unregister_method("wide_gate")
    assert "wide_gate" not in available_methods()
    with pytest.raises(ValueError):
        unregister_method("wide_gate")


def test_overwriting_a_builtin_and_restoring_it():
    register_method("naive", lambda **params: NaiveRegistration(sigma_floor=1.0), overwrite=True)
    try:
        assert make_method("naive").sigma_floor == 1.0
    finally:
        unregister_method("naive")
    assert make_method("naive").sigma_floor is None


def test_a_factory_must_give_an_estimator():
    register_method("not_an_estimator", lambda **params: object())
    try:
        with pytest.raises(TypeError, match="not an estimator"):
            make_method("not_an_estimator")
    finally:
        unregister_method("not_an_estimator")
    with pytest.raises(TypeError):
        register_method("x", 3)


def test_entry_point_methods_are_discovered_and_fit(plugin):
    names = available_methods()
    assert {"toy", "toy_class", "toy_broken", "toy_value"} <= set(names)
    assert names[: len(BUILTINS)] == BUILTINS
    scene = make_scene(n_objects=2, n_points=200, random_state=0)
    labels = make_method("toy", init=scene.labels).fit(scene.X).labels_
    assert np.array_equal(labels, NaiveRegistration(init=scene.labels).fit(scene.X).labels_)
    assert type(make_method("toy_class")).__name__ == "ToyRegistration"
    assert clone(make_method("toy_class", init="dbscan")).init == "dbscan"
    assert method_parameters("toy") == {"init", "random_state"}


def test_entry_points_that_fail_say_which(plugin):
    with pytest.raises(ImportError, match="toy_methods_plugin_missing:make"):
        make_method("toy_broken")
    with pytest.raises(TypeError, match="factory or an estimator class"):
        make_method("toy_value")


def test_entry_points_do_not_shadow_builtins(tmp_path, monkeypatch):
    install_plugin(
        tmp_path,
        monkeypatch,
        "shadow_methods_plugin",
        "from mmreg import TLinkage as make\n",
        {"naive": "shadow_methods_plugin:make"},
    )
    assert available_methods().count("naive") == 1
    assert type(make_method("naive")) is NaiveRegistration
