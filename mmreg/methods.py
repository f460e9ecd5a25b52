"""Registration methods by name: the built-ins, methods registered at run time and plugins.

A *method* is a factory ``f(**params) -> estimator`` that returns a new, unfitted
scikit-learn estimator (an estimator class is such a factory). The paper's scripts
(``paper/``) and anything else that compares methods look them up here by name, so a
third-party method takes part in every experiment without a change to mmreg:

* the built-ins (:data:`BUILTIN_METHODS`), the paper's five methods and mmreg's default;
* methods added at run time with :func:`register_method`;
* methods of installed packages, found through the entry-point group ``"mmreg.methods"``
  (:data:`ENTRY_POINT_GROUP`). Each entry point names a factory or an estimator class; in
  a package's ``pyproject.toml``::

      [project.entry-points."mmreg.methods"]
      my_method = "my_package.module:MyRegistration"

  It is loaded the first time :func:`make_method` asks for it.

A name given by several sources resolves in the order: registered at run time, built-in,
entry point.
"""

import inspect
from importlib.metadata import entry_points

from sklearn.base import clone

from mmreg.baselines import NaiveRegistration, SequentialRANSAC, TLinkage
from mmreg.estimators import MultiModelRegistration

__all__ = [
    "BUILTIN_METHODS",
    "ENTRY_POINT_GROUP",
    "available_methods",
    "make_method",
    "method_parameters",
    "register_method",
    "unregister_method",
]

ENTRY_POINT_GROUP = "mmreg.methods"


def _ours_vanilla(
    *, min_cluster_size=4, max_iter=10, init="euclidean", sigma_floor=None, random_state=None
):
    """The paper's "Ours (Vanilla)": Algorithm 1 without the distance gate (``tau=None``)."""
    return MultiModelRegistration(
        tau=None,
        min_cluster_size=min_cluster_size,
        max_iter=max_iter,
        init=init,
        variant="paper",
        sigma_floor=sigma_floor,
        random_state=random_state,
    )


def _ours(
    *,
    tau=1.5,
    min_cluster_size=4,
    max_iter=10,
    init="euclidean",
    sigma_floor=None,
    random_state=None,
):
    """The paper's "Ours": Algorithm 1 exactly, with the distance gate ``tau``."""
    return MultiModelRegistration(
        tau=tau,
        min_cluster_size=min_cluster_size,
        max_iter=max_iter,
        init=init,
        variant="paper",
        sigma_floor=sigma_floor,
        random_state=random_state,
    )


#: The built-in methods, in the paper's order: name -> factory.
BUILTIN_METHODS = {
    "naive": NaiveRegistration,
    "sequential_ransac": SequentialRANSAC,
    "t_linkage": TLinkage,
    "ours_vanilla": _ours_vanilla,
    "ours": _ours,
    "mmreg": MultiModelRegistration,
}

_registered = {}


def _plugins():
    """Entry points of the group, by name (the first of each name wins)."""
    found = {}
    for entry in entry_points(group=ENTRY_POINT_GROUP):
        found.setdefault(entry.name, entry)
    return found


def register_method(name, factory, *, overwrite=False):
    """Make ``factory`` available as method ``name`` for this session.

    Parameters
    ----------
    name : str
        Method name, as given to :func:`make_method` (and to ``--methods`` of the paper's
        scripts).
    factory : callable
        ``factory(**params)`` returns a new unfitted estimator; an estimator class will do.
    overwrite : bool, default=False
        Replace a method registered earlier under ``name`` (a built-in included) instead
        of raising.

    Returns
    -------
    factory : callable
        ``factory`` itself, so that ``register_method`` can decorate a function.

    Raises
    ------
    ValueError
        If ``name`` is taken (by a built-in or an earlier registration) and ``overwrite``
        is False.

    See Also
    --------
    make_method : Build an estimator of a registered method.

    Examples
    --------
    >>> from mmreg import MultiModelRegistration
    >>> from mmreg.methods import make_method, register_method
    >>> def small_gate(**params):
    ...     return MultiModelRegistration(tau=0.5, **params)
    >>> _ = register_method("small_gate", small_gate, overwrite=True)
    >>> make_method("small_gate", max_iter=5)
    MultiModelRegistration(max_iter=5, tau=0.5)
    >>> unregister_method("small_gate")
    """
    if not isinstance(name, str) or not name:
        raise TypeError(f"name must be a non-empty string; got {name!r}.")
    if not callable(factory):
        raise TypeError(f"factory must be callable; got {type(factory).__name__}.")
    if not overwrite and (name in _registered or name in BUILTIN_METHODS):
        raise ValueError(
            f"A method named {name!r} exists already; pass overwrite=True to replace it."
        )
    _registered[name] = factory
    return factory


def unregister_method(name):
    """Forget a method added with :func:`register_method`.

    Built-ins and entry points cannot be removed; a built-in that was overwritten comes
    back.

    Parameters
    ----------
    name : str

    Raises
    ------
    ValueError
        If ``name`` was not registered with :func:`register_method`.

    Examples
    --------
    >>> from mmreg.methods import available_methods, register_method, unregister_method
    >>> _ = register_method("copy_of_ours", lambda **params: None)
    >>> unregister_method("copy_of_ours")
    >>> "copy_of_ours" in available_methods()
    False
    """
    if name not in _registered:
        raise ValueError(f"No method {name!r} was registered with register_method.")
    del _registered[name]


def available_methods():
    """Names of every method :func:`make_method` can build.

    Returns
    -------
    names : list of str
        The built-ins in the paper's order (``"naive"``, ``"sequential_ransac"``,
        ``"t_linkage"``, ``"ours_vanilla"``, ``"ours"``, ``"mmreg"``), then the methods
        registered with :func:`register_method` and those of the ``"mmreg.methods"``
        entry points, sorted. Entry points are listed, not loaded.

    Examples
    --------
    >>> from mmreg.methods import available_methods
    >>> available_methods()[:6]
    ['naive', 'sequential_ransac', 't_linkage', 'ours_vanilla', 'ours', 'mmreg']
    """
    others = (set(_registered) | set(_plugins())) - set(BUILTIN_METHODS)
    return [*BUILTIN_METHODS, *sorted(others)]


def _factory(name):
    if name in _registered:
        return _registered[name]
    if name in BUILTIN_METHODS:
        return BUILTIN_METHODS[name]
    plugin = _plugins().get(name)
    if plugin is None:
        raise ValueError(
            f"Unknown method {name!r}; available methods: {', '.join(available_methods())}."
        )
    try:
        factory = plugin.load()
    except Exception as exc:
        raise ImportError(
            f"The entry point {plugin.value!r} of method {name!r} (group "
            f"{ENTRY_POINT_GROUP!r}) could not be loaded: {exc}"
        ) from exc
    if not callable(factory):
        raise TypeError(
            f"The entry point {plugin.value!r} of method {name!r} must name a factory or an "
            f"estimator class; it names a {type(factory).__name__}."
        )
    return factory


def method_parameters(name):
    """Names of the parameters that method ``name`` accepts.

    Read from the factory's signature; for a factory that takes ``**params`` (and so
    could take anything), from ``get_params`` of the estimator it builds by default.

    Parameters
    ----------
    name : str
        A name from :func:`available_methods`.

    Returns
    -------
    params : frozenset of str

    Examples
    --------
    >>> from mmreg.methods import method_parameters
    >>> sorted(method_parameters("ours_vanilla"))
    ['init', 'max_iter', 'min_cluster_size', 'random_state', 'sigma_floor']
    >>> "tau" in method_parameters("ours")
    True
    """
    factory = _factory(name)
    try:
        signature = inspect.signature(factory)
    except (TypeError, ValueError):  # some builtins have no signature
        signature = None
    if signature is not None:
        kinds = {p.kind for p in signature.parameters.values()}
        if inspect.Parameter.VAR_KEYWORD not in kinds:
            return frozenset(
                p.name
                for p in signature.parameters.values()
                if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)
            )
    return frozenset(factory().get_params(deep=False))


def make_method(name, *, strict=True, **params):
    """A new, unfitted estimator of method ``name``.

    Parameters
    ----------
    name : str
        One of :func:`available_methods`: a built-in, a method registered with
        :func:`register_method` or an entry point of the ``"mmreg.methods"`` group:

        ``"naive"``
            :class:`~mmreg.NaiveRegistration`, Horn's method per initial cluster.
        ``"sequential_ransac"``
            :class:`~mmreg.SequentialRANSAC` (paper: ``residual_threshold`` 0.01
            noiseless, 0.5 noisy, 0.2 on flow scenes; ``max_trials=1000``).
        ``"t_linkage"``
            :class:`~mmreg.TLinkage` (paper: ``tau_t`` 0.2 m, 1 m on flow scenes).
        ``"ours_vanilla"``
            :class:`~mmreg.MultiModelRegistration` with ``variant="paper"`` and
            ``tau=None``: Algorithm 1 without the distance gate.
        ``"ours"``
            :class:`~mmreg.MultiModelRegistration` with ``variant="paper"``: Algorithm 1
            exactly (paper: ``tau`` 1.5 m, 5 m on flow scenes; ``min_cluster_size=4``,
            ``max_iter=10``).
        ``"mmreg"``
            :class:`~mmreg.MultiModelRegistration` as it comes (``variant="sweep"``).
    strict : bool, default=True
        If False, parameters the method does not take (:func:`method_parameters`) are
        dropped instead of raising: a script can hand every method one set of parameters
        (``init``, ``tau``, ``random_state``, ...) and each takes what it knows.
    **params
        Parameters of the method, e.g. ``init``, ``tau``, ``random_state``.

    Returns
    -------
    estimator : estimator
        Unfitted, with ``get_params`` and ``fit``, so :func:`sklearn.base.clone` works.

    Raises
    ------
    ValueError
        If ``name`` is unknown; the message lists the available methods.
    TypeError
        If ``strict`` and the method does not take one of ``params``, or if the factory
        does not return an estimator.

    See Also
    --------
    available_methods : The names.
    register_method : Add a method.

    Examples
    --------
    >>> from sklearn.base import clone
    >>> from mmreg.methods import make_method
    >>> make_method("ours", tau=5.0)
    MultiModelRegistration(tau=5.0, variant='paper')
    >>> make_method("ours_vanilla")
    MultiModelRegistration(tau=None, variant='paper')
    >>> clone(make_method("sequential_ransac", residual_threshold=0.01, random_state=0))
    SequentialRANSAC(random_state=0, residual_threshold=0.01)
    >>> make_method("naive", tau=1.5, strict=False)  # NaiveRegistration has no tau
    NaiveRegistration()
    """
    factory = _factory(name)
    if not strict:
        accepted = method_parameters(name)
        params = {key: value for key, value in params.items() if key in accepted}
    try:
        estimator = factory(**params)
    except TypeError as exc:
        if strict:
            accepted = ", ".join(sorted(method_parameters(name)))
            raise TypeError(
                f"Method {name!r} cannot take the parameters {sorted(params)} ({exc}); it "
                f"takes: {accepted}. Pass strict=False to drop the others."
            ) from exc
        raise
    if not (hasattr(estimator, "fit") and hasattr(estimator, "get_params")):
        raise TypeError(
            f"The factory of method {name!r} returned a {type(estimator).__name__}, not an "
            "estimator with fit and get_params."
        )
    try:
        clone(estimator)
    except RuntimeError as exc:  # a constructor that changes its parameters
        raise TypeError(f"Method {name!r} gives an estimator that cannot be cloned: {exc}") from exc
    return estimator
