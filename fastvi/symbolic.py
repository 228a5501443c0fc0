r"""Models from SymPy expressions, with every derivative generated (optional extra ``sym``).

Writing the callbacks of a :class:`fastvi.Model` by hand means writing up to ten functions,
seven of them derivatives; :func:`model_from_lagrangian` writes them from the kinetic
energy (or mass matrix), the potential and the constraints:

.. code-block:: python

    import sympy as sp
    from fastvi.symbolic import model_from_lagrangian, velocities

    x, th = sp.symbols("x theta")
    vx, vth = velocities([x, th])
    M, m, l, g = sp.symbols("M m l g", positive=True)
    T = (M + m) * vx**2 / 2 + m * l * sp.cos(th) * vx * vth + m * l**2 * vth**2 / 2
    V = -m * g * l * sp.cos(th)
    cart = model_from_lagrangian([x, th], T, V, v=[vx, vth],
                                 params={M: 2.0, m: 1.0, l: 1.0, g: 9.81})

The derivatives (``∂T/∂q``, ``∂²T/∂q²``, ``∂(M v)/∂q``, ``∇V``, ``∇²V``, ``G = ∂g/∂q``,
``Σ η_a ∇²g_a``) and the derivatives of the callbacks by the parameters
(``param_derivatives`` of :class:`fastvi.Model`) are differentiated symbolically, common subexpressions are eliminated
(``sympy.cse``), and each callback is printed as Python source (``math`` functions,
``q[i]``, ``v[i]``, ``p[k]``), executed into a private module namespace and handed to
:class:`fastvi.Model`, which compiles it with numba exactly like a hand-written one. The
generated source is kept in ``model.source``: print it to see (or copy) what runs.

SymPy is imported only inside this module, when a model is built; a built model pickles
as its source text, so worker processes do not need SymPy.
"""

from __future__ import annotations

import hashlib
import linecache
import math
from collections.abc import Mapping

import numpy as np

from .model import PARAM_SLOTS, PATTERNED_PARAM_SLOTS, SLOTS, Model

__all__ = ["model_from_lagrangian", "velocities", "SymbolicModel"]


def _sympy():
    try:
        import sympy
    except ImportError:  # pragma: no cover - sympy is installed in the dev environment
        raise ImportError(
            "fastvi.symbolic needs SymPy: install the optional extra with `pip install fastvi[sym]`"
        ) from None
    return sympy


def velocities(q):
    """Velocity symbols ``<name>_dot`` for the coordinate symbols ``q``.

    Parameters
    ----------
    q : sequence of sympy.Symbol
        The generalized coordinates.

    Returns
    -------
    tuple of sympy.Symbol
        One real symbol per coordinate, named ``<name>_dot``.
    """
    sp = _sympy()
    return tuple(sp.Symbol(f"{s.name}_dot", real=True) for s in _symbols(q, "q"))


def _symbols(seq, name: str):
    sp = _sympy()
    if isinstance(seq, sp.Basic) and not isinstance(seq, sp.MatrixBase):
        seq = [seq]
    seq = list(seq)
    for s in seq:
        if not isinstance(s, sp.Symbol):
            raise TypeError(f"`{name}` must be a sequence of sympy Symbols, got {s!r} ({type(s).__name__})")
    if len(set(seq)) != len(seq):
        raise ValueError(f"`{name}` contains a symbol twice: {seq}")
    return seq


class SymbolicModel(Model):
    """A :class:`fastvi.Model` whose callbacks are generated Python source.

    Built by :func:`model_from_lagrangian`; everything a ``Model`` does works unchanged.

    Parameters
    ----------
    source : str
        Python source defining the callbacks (functions named after :data:`fastvi.model.SLOTS`)
        and their derivatives by the parameters (``<slot>_by_params``, a function or ``0``,
        for the slots of :data:`fastvi.model.PARAM_SLOTS`).
    n, m : int
        Coordinates and constraints.
    params : array_like (k,)
        Parameter values, in the order of ``param_names``.
    mass : ndarray (n, n), optional
        Constant mass matrix (when ``source`` defines no ``mass`` function).
    name : str
    coordinates, param_names : tuple of str
        Names of the coordinate and parameter symbols (``q[i]`` and ``p[k]`` in ``source``).
    constraint_jacobian_pattern : ndarray (m, n) of bool, optional
        The structural non-zeros of ``G``, which the generated ``constraint_jacobian`` writes
        alone (see :class:`fastvi.Model`).
    param_patterns : mapping, optional
        The structural non-zeros of the generated derivatives by θ of ``kinetic_grad``,
        ``potential_grad`` and ``constraint``, which they write alone (``Model``'s
        ``param_patterns``).

    Attributes
    ----------
    source : str
        The generated Python source; ``print(model.source)`` shows what numba compiles.
    coordinates, param_names : tuple of str
    """

    def __init__(self, source: str, n: int, m: int, *, params=(), mass=None, name: str = "symbolic",
                 coordinates=(), param_names=(), constraint_jacobian_pattern=None,
                 param_patterns=None):
        namespace = _load(source, name)
        funcs = {slot: namespace[slot] for slot in SLOTS if slot in namespace}
        by_params = {slot: namespace[_BY_PARAMS.format(slot)] for slot in PARAM_SLOTS
                     if _BY_PARAMS.format(slot) in namespace}
        if "mass" in funcs:
            mass = funcs.pop("mass")
        super().__init__(n, m, params=params, mass=mass, name=name,
                         constraint_jacobian_pattern=constraint_jacobian_pattern,
                         param_derivatives=by_params or None, param_patterns=param_patterns,
                         **funcs)
        self.source = source
        self.coordinates = tuple(coordinates)
        self.param_names = tuple(param_names)

    def __reduce__(self):
        # The generated functions live in a private namespace that other processes cannot
        # import: travel as the source text and re-exec it on arrival (no SymPy needed).
        return (_rebuild, (self.source, self.n, self.m, dict(
            params=self.params, mass=self.mass_matrix_constant, name=self.name,
            coordinates=self.coordinates, param_names=self.param_names,
            constraint_jacobian_pattern=self.constraint_jacobian_pattern,
            param_patterns=self.param_patterns)))


#: the name in generated source of the derivative by the parameters of a callback
_BY_PARAMS = "{}_by_params"


def _rebuild(source, n, m, kwargs):
    return SymbolicModel(source, n, m, **kwargs)


def _load(source: str, name: str) -> dict:
    """Execute generated source into a fresh module-like namespace."""
    digest = hashlib.sha1(source.encode()).hexdigest()[:12]
    filename = f"<fastvi.symbolic {name} {digest}>"
    # Registered with linecache so tracebacks and numba's error messages can show the lines.
    linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
    namespace = {"__name__": f"fastvi.symbolic.generated_{digest}", "math": math}
    exec(compile(source, filename, "exec"), namespace)  # noqa: S102 - our own generated code
    return namespace


def _params(params):
    sp = _sympy()
    if params is None:
        return [], np.zeros(0)
    items = list(params.items()) if isinstance(params, Mapping) else [tuple(x) for x in params]
    syms, vals = [], []
    for item in items:
        if len(item) != 2:
            raise ValueError(f"`params` must map symbols to values, got the item {item!r}")
        s, val = item
        if not isinstance(s, sp.Symbol):
            raise TypeError(f"`params` keys must be sympy Symbols, got {s!r}")
        try:
            val = float(val)
        except (TypeError, ValueError):
            raise TypeError(f"`params` value of {s} must be a number, got {val!r}") from None
        if not math.isfinite(val):
            raise ValueError(f"`params` value of {s} must be finite, got {val}")
        syms.append(s)
        vals.append(val)
    if len(set(syms)) != len(syms):
        raise ValueError(f"`params` contains a symbol twice: {syms}")
    return syms, np.array(vals)


class _Writer:
    """Prints callbacks as Python functions with common subexpressions eliminated."""

    def __init__(self, replace: dict):
        sp = _sympy()
        from sympy.printing.pycode import PythonCodePrinter

        self.sp = sp
        self.replace = replace
        self.printer = PythonCodePrinter({"fully_qualified_modules": True})
        self.blocks: list[str] = []
        #: {slot: boolean (k, size)}: the structural non-zeros of the derivatives by θ of
        #: vector callbacks, the only entries their functions write (Model's param_patterns)
        self.param_patterns: dict = {}

    def _expr(self, e):
        return self.printer.doprint(e)

    def function(self, name: str, args: str, outputs, shape=None, doc: str = "",
                 zeroed: bool = False):
        """``outputs``: list of (targets, expr); ``shape`` set means ``out`` is zero-filled
        first and zero entries are skipped (not filled when ``zeroed``: the kernels hand a
        zero ``out``, as for a declared pattern). ``shape=None`` with one output means a
        return."""
        sp = self.sp
        outputs = [(t, sp.sympify(e).xreplace(self.replace)) for t, e in outputs]
        n_all = sum(len(t) for t, _ in outputs)
        if shape is not None:
            outputs = [(t, e) for t, e in outputs if e != 0]
        zero_fill = shape is not None and not zeroed and sum(len(t) for t, _ in outputs) < n_all
        exprs = [e for _, e in outputs]
        repl, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("x")) if exprs else ([], [])
        lines = [f"def {name}({args}):", f'    """{doc}"""']
        lines += [f"    {s} = {self._expr(e)}" for s, e in repl]
        if shape is None:
            (e,) = reduced
            lines.append(f"    return {float(e)!r}" if e.is_number else f"    return {self._expr(e)}")
        else:
            if zero_fill:  # only the nonzero entries are written below
                lines.append(f"    out[{', '.join(':' * len(shape))}] = 0.0")
            for (targets, _), e in zip(outputs, reduced):
                lines.append(f"    {targets[0]} = {self._expr(e)}")
                lines += [f"    {t} = {targets[0]}" for t in targets[1:]]  # symmetric partner
        self.blocks.append("\n".join(lines))

    def by_params(self, slot: str, args: str, outputs, shape, psyms):
        """The derivative by each parameter of the callback ``slot`` whose entries are
        ``outputs`` (``(targets, expr)``, ``out`` of ``shape``): a function
        ``<slot>_by_params`` writing ``out[l, …] = ∂f/∂θ_l`` (shape ``(k,) + shape``), or the
        declaration ``<slot>_by_params = 0`` when no entry depends on the parameters."""
        sp = self.sp
        name = _BY_PARAMS.format(slot)
        derived = [(tuple(t.replace("out[", f"out[{l}, ", 1) for t in targets), sp.diff(sp.sympify(e), s))
                   for l, s in enumerate(psyms) for targets, e in outputs]
        if all(e == 0 for _, e in derived):
            self.blocks.append(f"# {slot} does not depend on the parameters\n{name} = 0")
            return
        patterned = slot in PATTERNED_PARAM_SLOTS
        if patterned:  # a vector callback: entry i of row l is derived[l * size + i]
            nonzero = [sp.sympify(e).xreplace(self.replace) != 0 for _, e in derived]
            self.param_patterns[slot] = np.array(nonzero, dtype=bool).reshape(len(psyms), *shape)
        self.function(name, args, derived, (len(psyms),) + tuple(shape),
                      f"∂({slot})/∂θ_l in out[l]" + (" (the entries of its pattern)" if patterned else ""),
                      zeroed=patterned)


def _vector_outputs(exprs):
    return [((f"out[{i}]",), e) for i, e in enumerate(exprs)]


def _matrix_outputs(A, symmetric: bool):
    rows, cols = A.shape
    outs = []
    for i in range(rows):
        for j in range(cols):
            if symmetric and j < i:
                continue
            targets = (f"out[{i}, {j}]",) if not symmetric or i == j else (f"out[{i}, {j}]", f"out[{j}, {i}]")
            outs.append((targets, A[i, j]))
    return outs


def model_from_lagrangian(q, T, V=0, constraints=(), *, v=None, params=None, name: str = "symbolic",
                          exact_hessians: bool = True, param_derivatives: bool = True,
                          compile: bool = True) -> SymbolicModel:
    r"""Build a :class:`fastvi.Model` from ``L = T − V`` and constraints ``g(q) = 0`` in SymPy.

    Parameters
    ----------
    q : sequence of sympy.Symbol
        The n generalized (possibly redundant) coordinates.
    T : sympy expression or sympy Matrix
        Kinetic energy ``T(q, v) = ½ vᵀ M(q) v``, a homogeneous quadratic in the velocity
        symbols ``v``; or directly the symmetric mass matrix ``M(q)`` (n × n).
    V : sympy expression, default 0
        Potential energy ``V(q)``.
    constraints : sequence of sympy expressions, default ()
        The m holonomic constraints ``g_a(q) = 0``.
    v : sequence of sympy.Symbol, optional
        The velocity symbols ``T`` is written in (required when ``T`` is an expression; see
        :func:`velocities`).
    params : dict {sympy.Symbol: float} or sequence of (Symbol, float), optional
        Parameters and their values; they become the model's ``params`` vector in this
        order, so runs can change them (``integrate(..., params=...)``) without rebuilding.
        A mass matrix that does not depend on ``q`` is evaluated once with these values
        (a constant matrix lets the kernels skip every kinetic-energy callback), so
        changing a parameter that enters only ``M`` needs a new model.
    name : str, default "symbolic"
        Model name (summaries, error messages).
    exact_hessians : bool, default True
        Generate the four second-derivative callbacks (``potential_hessian``,
        ``constraint_hessian``, ``kinetic_hessian``, ``momentum_jacobian``); with False the
        kernels finite-difference the first derivatives instead. A potential linear in q
        (∇²V = 0, e.g. gravity in Cartesian coordinates) is declared ``potential_hessian=0``
        instead of a callback: the kernels then evaluate ∇V once a trajectory.
    param_derivatives : bool, default True
        Generate the derivatives by the parameters of every callback they can enter
        (``Model(param_derivatives=...)``: ``∂M/∂θ`` and ``∂(∂T/∂q)/∂θ`` when ``M``
        depends on ``q``, ``∂(∇V)/∂θ``, ``∂g/∂θ``, ``∂G/∂θ``; ``0`` where one does not
        depend on θ), so the sensitivities and the adjoint linearise the step exactly in θ.
        Compiled when first needed, not by ``compile``.
    compile : bool, default True
        Compile the callbacks with numba now (about a second), so that an expression numba
        cannot compile fails here rather than at the first integration.

    Returns
    -------
    SymbolicModel
        A :class:`fastvi.Model`; ``model.source`` holds the generated code.

    Raises
    ------
    ValueError
        If ``T`` is not a homogeneous quadratic in ``v``, ``M`` is not symmetric or
        depends on ``v``, or an expression contains a symbol that is neither a
        coordinate, a velocity nor a parameter (the message names it).

    Notes
    -----
    Generated callbacks, with ``T = ½ vᵀ M(q) v``:
    ``kinetic_grad_i = ∂T/∂q_i``, ``kinetic_hessian_ij = ∂²T/∂q_i∂q_j``,
    ``momentum_jacobian_ab = ∂(M v)_a/∂q_b``, ``potential_grad = ∇V``,
    ``potential_hessian = ∇²V``, ``constraint_jacobian_ai = ∂g_a/∂q_i`` and
    ``constraint_hessian = Σ_a η_a ∇²g_a``; ``<slot>_by_params`` writes
    ``out[l, …] = ∂f/∂θ_l`` for each first-order callback ``f`` and ``M``. Each
    callback's expressions go through one ``sympy.cse`` call, so shared subexpressions
    (``sin θ``, ``cos θ``, …) are computed once per call.

    Examples
    --------
    >>> import sympy as sp
    >>> from fastvi.symbolic import model_from_lagrangian
    >>> x, y, m, g, l = sp.symbols("x y m g l")
    >>> pend = model_from_lagrangian([x, y], sp.eye(2) * m, m * g * y,
    ...                              [(x**2 + y**2 - l**2) / 2],
    ...                              params={m: 1.0, g: 9.81, l: 1.0}, compile=False)
    >>> pend.n, pend.m, pend.mass_matrix_constant.tolist()
    (2, 1, [[1.0, 0.0], [0.0, 1.0]])
    """
    sp = _sympy()
    qs = _symbols(q, "q")
    n = len(qs)
    if n == 0:
        raise ValueError("`q` must contain at least one coordinate symbol")
    psyms, pvals = _params(params)
    overlap = set(psyms) & set(qs)
    if overlap:
        raise ValueError(f"`params` and `q` share the symbols {sorted(map(str, overlap))}")

    if isinstance(T, sp.MatrixBase) or isinstance(T, (list, tuple, np.ndarray)):
        M = sp.Matrix(T)
        if M.shape != (n, n):
            raise ValueError(f"`T` given as a mass matrix must be {n} x {n}, got {M.shape[0]} x {M.shape[1]}")
        if not (M - M.T).applyfunc(sp.simplify).is_zero_matrix:
            raise ValueError("`T` given as a mass matrix must be symmetric")
        vs = _symbols(v, "v") if v is not None else list(velocities(qs))
    else:
        if v is None:
            raise ValueError("`v` (the velocity symbols `T` is written in) is required when `T` "
                             "is an expression; create them with fastvi.symbolic.velocities(q)")
        vs = _symbols(v, "v")
        T = sp.sympify(T)
        poly = T.expand().as_poly(*vs) if len(vs) else None
        if len(vs) != n:
            raise ValueError(f"`v` must have one symbol per coordinate ({n}), got {len(vs)}")
        if poly is None or any(sum(mon) != 2 for mon in poly.monoms()):
            raise ValueError("`T` must be a homogeneous quadratic form ½ vᵀ M(q) v in the velocity "
                             f"symbols {vs}, got {T}")
        M = sp.hessian(T, vs)
    if set(vs) & (set(qs) | set(psyms)):
        raise ValueError("`v` must not share symbols with `q` or `params`")
    V = sp.sympify(V)
    gs = [sp.sympify(c) for c in (constraints if isinstance(constraints, (list, tuple)) else [constraints])]
    m = len(gs)

    known = set(qs) | set(psyms)
    for label, exprs in (("the mass matrix (from `T`)", list(M)), ("`V`", [V]), ("`constraints`", gs)):
        extra = set().union(*(e.free_symbols for e in exprs)) - known
        if extra & set(vs):
            raise ValueError(f"{label} must not depend on the velocities {sorted(map(str, extra & set(vs)))}")
        if extra:
            raise ValueError(f"{label} contains the symbols {sorted(map(str, extra))}, which are "
                             "neither coordinates `q` nor `params`; add them to `params`")

    qb, vb, pb, eb = (sp.IndexedBase(s) for s in ("q", "v", "p", "eta"))
    replace = {s: qb[i] for i, s in enumerate(qs)}
    replace.update({s: vb[i] for i, s in enumerate(vs)})
    replace.update({s: pb[k] for k, s in enumerate(psyms)})
    w = _Writer(replace)
    by_params = param_derivatives and bool(psyms)
    eta = [sp.Dummy(f"eta{a}") for a in range(m)]
    w.replace.update({e: eb[a] for a, e in enumerate(eta)})

    mass_depends_on_q = any(e.free_symbols & set(qs) for e in M)
    mass_const = None
    if mass_depends_on_q:
        vvec = sp.Matrix(vs)
        Tq = (vvec.T * M * vvec)[0, 0] / 2
        Mv = M * vvec
        mass_out = _matrix_outputs(M, True)
        kgrad_out = _vector_outputs([sp.diff(Tq, s) for s in qs])
        w.function("mass", "q, p, out", mass_out, (n, n), "M(q)")
        w.function("kinetic_grad", "q, v, p, out", kgrad_out, (n,), "∂T/∂q, T = ½ vᵀ M(q) v")
        if by_params:
            w.by_params("mass", "q, p, out", mass_out, (n, n), psyms)
            w.by_params("kinetic_grad", "q, v, p, out", kgrad_out, (n,), psyms)
        if exact_hessians:
            w.function("kinetic_hessian", "q, v, p, out", _matrix_outputs(sp.hessian(Tq, qs), True), (n, n),
                       "∂²T/∂q²")
            w.function("momentum_jacobian", "q, v, p, out", _matrix_outputs(Mv.jacobian(qs), False), (n, n),
                       "∂(M(q) v)_a/∂q_b")
    else:
        values = dict(zip(psyms, pvals))
        try:
            mass_const = np.array(M.xreplace(values).evalf(), dtype=np.float64)
        except TypeError:
            raise ValueError(f"the mass matrix could not be evaluated to numbers with `params`: {M}") from None
    w.function("potential", "q, p", [((), V)], None, "V(q)")
    pgrad_out = _vector_outputs([sp.diff(V, s) for s in qs])
    w.function("potential_grad", "q, p, out", pgrad_out, (n,), "∇V")
    if by_params:
        w.by_params("potential_grad", "q, p, out", pgrad_out, (n,), psyms)
    if exact_hessians:
        HV = sp.hessian(V, qs)
        if HV.is_zero_matrix:
            # declared, not a callback: the kernels then evaluate ∇V once a trajectory
            w.blocks.append("# ∇²V = 0: V is linear in q (fastvi.Model's potential_hessian=0)\n"
                            "potential_hessian = 0")
        else:
            w.function("potential_hessian", "q, p, out", _matrix_outputs(HV, True), (n, n), "∇²V")
    if m:
        Gm = sp.Matrix(gs).jacobian(qs)
        w.function("constraint", "q, p, out", _vector_outputs(gs), (m,), "g(q)")
        if by_params:
            w.by_params("constraint", "q, p, out", _vector_outputs(gs), (m,), psyms)
            # not zeroed: the pattern of G need not be that of its derivatives by θ
            w.by_params("constraint_jacobian", "q, p, out", _matrix_outputs(Gm, False), (m, n), psyms)
        # the structural non-zeros of G are its declared pattern: the callback writes only
        # them (O(nnz) instead of O(m n) a call) and the structured solves take it as it is
        pattern = np.array([[Gm[a, i].xreplace(replace) != 0 for i in range(n)] for a in range(m)],
                           dtype=bool)
        w.function("constraint_jacobian", "q, p, out", _matrix_outputs(Gm, False), (m, n),
                   "G = ∂g/∂q (only the entries of the pattern: out is zero elsewhere)", zeroed=True)
        if exact_hessians:
            H = sp.zeros(n, n)
            for a, ga in enumerate(gs):
                H += eta[a] * sp.hessian(ga, qs)
            # within the pattern G's implies (Model.constraint_hessian_pattern), which the
            # kernels hand zeroed: its structural non-zeros alone, no O(n²) fill
            w.function("constraint_hessian", "q, eta, p, out", _matrix_outputs(H, True), (n, n),
                       "Σ_a η_a ∇²g_a (only the non-zeros: out is zero elsewhere)", zeroed=True)

    header = (f"# Generated by fastvi.symbolic.model_from_lagrangian for the model {name!r}.\n"
              f"# q = ({', '.join(map(str, qs))}); v = ({', '.join(map(str, vs))}); "
              f"p = ({', '.join(map(str, psyms))})\n"
              "import math\n")
    source = header + "\n\n" + "\n\n\n".join(w.blocks) + "\n"
    model = SymbolicModel(source, n, m, params=pvals, mass=mass_const, name=name,
                          coordinates=[s.name for s in qs], param_names=[s.name for s in psyms],
                          constraint_jacobian_pattern=pattern if m else None,
                          param_patterns=w.param_patterns or None)
    if compile:
        model.kernel_arguments()
    return model
