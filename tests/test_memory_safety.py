"""Memory safety at the model boundary: size mistakes raise, they never corrupt memory.

The callbacks are compiled with their sizes baked in and no bounds checks, so before the
guarded check these mistakes ended in ``double free or corruption``, segmentation faults, or
a "successful" run that crashed at exit (this script before the fix: signals 11 and 6 for the
first three mistakes, by either route; the unwritten constraint entry was blamed on the
Jacobian). Corruption is not deterministic, hence the mistakes run in fresh processes: one
process a route, the mistakes one after another, in ``make test``; each mistake alone in
its own process, three times, in ``make test-slow``. Every run must end in a Python
exception (exit code 1) with the expected message: never a signal (negative code), never
success (0).
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fastvi

ROOT = Path(__file__).resolve().parents[1]

# A point on the unit sphere (n = 3) with the potential V = g z + x² y², and the four mistakes.
SCRIPT = r'''
import sys
import numpy as np
import fastvi

case, route = sys.argv[1], sys.argv[2]

def V(q, p):
    return p[0] * q[2] + q[0] * q[0] * q[1] * q[1]

def dV(q, p, out):
    out[0] = 2.0 * q[0] * q[1] * q[1]
    out[1] = 2.0 * q[0] * q[0] * q[1]
    out[2] = p[0]

def dV_past_n(q, p, out):  # loops over n + 1 entries
    for i in range(4):
        out[i] = 0.0
    out[0] = 2.0 * q[0] * q[1] * q[1]
    out[1] = 2.0 * q[0] * q[0] * q[1]
    out[2] = p[0]

def g2(q, p, out):  # two constraints: the sphere and the saddle z = 0.7 x y
    out[0] = 0.5 * (q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1.0)
    out[1] = q[2] - 0.7 * q[0] * q[1]

def G2(q, p, out):
    out[0, 0] = q[0]
    out[0, 1] = q[1]
    out[0, 2] = q[2]
    out[1, 0] = -0.7 * q[1]
    out[1, 1] = -0.7 * q[0]
    out[1, 2] = 1.0

def g2_forgets_last(q, p, out):
    out[0] = 0.5 * (q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1.0)

def g1(q, p, out):
    out[0] = 0.5 * (q[0] ** 2 + q[1] ** 2 + q[2] ** 2 - 1.0)

def G1(q, p, out):
    out[0, 0] = q[0]
    out[0, 1] = q[1]
    out[0, 2] = q[2]

def G1_transposed(q, p, out):  # written as an (n, m) = (3, 1) array
    for b in range(3):
        out[b, 0] = q[b]

funcs = dict(potential=V, potential_grad=dV)
if case == "m_too_small":  # two constraints written, m = 1 declared
    m, funcs = 1, dict(funcs, constraint=g2, constraint_jacobian=G2)
elif case == "gradient_past_n":
    m, funcs = 1, dict(funcs, constraint=g1, constraint_jacobian=G1, potential_grad=dV_past_n)
elif case == "jacobian_transposed":
    m, funcs = 1, dict(funcs, constraint=g1, constraint_jacobian=G1_transposed)
elif case == "constraint_unwritten":
    m, funcs = 2, dict(funcs, constraint=g2_forgets_last, constraint_jacobian=G2)
else:  # "correct": the same model without a mistake
    m, funcs = 1, dict(funcs, constraint=g1, constraint_jacobian=G1)
model = fastvi.Model(3, m, params=(9.81,), mass=np.eye(3), **funcs)
q0, v0 = np.array([0.6, 0.8, 0.0]), np.array([-0.8, 0.6, 0.0])  # on the sphere, tangent
if route == "integrate":  # the default path: the automatic check on first use
    result = fastvi.integrate(model, q0, v0, h=0.01, n_steps=1)
    print("integrated", result.success)
elif route == "nocheck":  # check=False skips the derivatives, never the size guard
    result = fastvi.integrate(model, q0, v0, h=0.01, n_steps=50, check=False)
    print("integrated", result.success)
else:
    model.check(q0, v0)
    print("check passed")
'''

CASES = {
    "m_too_small": r"`constraint` wrote 2 entries but the model declares m = 1 \(out shape \(1,\)\); check `m`",
    "gradient_past_n": r"`potential_grad` wrote 4 entries but the model declares n = 3 \(out shape \(3,\)\)",
    "jacobian_transposed": r"`constraint_jacobian` wrote past the end of its output.*m = 1, n = 3 "
                           r"\(out shape \(1, 3\).*wrong shape or transposed\?.*\(3, 1\) array",
    "constraint_unwritten": r"`constraint` never wrote entry \[1\] of its output \(out shape \(2,\)",
}


# Event functions on the correct sphere model of SCRIPT (its functions reused): each mistake
# of the issue, and SciPy's habit. argv: the event's name, then "check" or "nocheck".
EVENT_SCRIPT = SCRIPT.split("funcs = dict(")[0] + r'''
def reads_past_v(t, q, v, p):  # v has n = 3 entries
    return v[3] - 0.5

def writes_v(t, q, v, p):
    v[0] = 0.0
    return q[0]

def writes_q(t, q, v, p):
    q[2] = 1.0
    return q[0]

def scipy_style(t, y):
    return y[0]

def correct(t, q, v, p):
    return q[0]

model = fastvi.Model(3, 1, params=(9.81,), mass=np.eye(3), potential=V, potential_grad=dV,
                     constraint=g1, constraint_jacobian=G1)
q0, v0 = np.array([0.6, 0.8, 0.0]), np.array([-0.8, 0.6, 0.0])
result = fastvi.integrate(model, q0, v0, h=0.01, n_steps=200, events=globals()[case],
                          check=route == "check")
print("integrated", result.success, len(result.t_events[0]))
'''

EVENT_CASES = {
    "reads_past_v": r"`events\[0\]` reads past the end of `q` or `v`.*n = 3 entries",
    "writes_v": r"`events\[0\]` wrote into its input `v` \(entry 0\)",
    "writes_q": r"`events\[0\]` wrote into its input `q` \(entry 2\)",
    "scipy_style": r"takes 2 positional arguments — SciPy's solve_ivp convention `ev\(t, y\)`.*"
                   r"event\(t, q, v, params\)",
}


def _run_all(jobs, script=SCRIPT):
    """Run ``(case, route)`` jobs in fresh processes, two at a time (numba import and compiling
    the model's callbacks take a few seconds each): ``[(job, returncode, stdout, stderr)]``."""
    results, pending = [], list(jobs)
    while pending:
        batch, pending = pending[:2], pending[2:]
        procs = [(job, _start(script, *job)) for job in batch]
        for job, proc in procs:
            out, err = proc.communicate(timeout=600)
            results.append((job, proc.returncode, out, err))
    return results


# Runs the script once per job in one fresh process, each job's output after a marker line.
BATCH = r'''
import sys, traceback
script, jobs = sys.argv[1], sys.argv[2:]
for job in jobs:
    sys.argv = ["-c"] + job.split(":")
    for stream in (sys.stdout, sys.stderr):
        print("=== job " + job, file=stream, flush=True)
    try:
        exec(script, {"__name__": "__main__"})
        code = 0
    except Exception:
        traceback.print_exc()
        code = 1
    sys.stderr.flush()
    print("=== exit", code, flush=True)
'''


def _run_in_one_process(jobs, script=SCRIPT):
    """The jobs of :func:`_run_all` one after the other in a single fresh process (the import and
    the kernels' loading paid once): the same ``[(job, returncode, stdout, stderr)]``, with
    returncode 1 for a job that raised, 0 for one that ran through, and the process's own code
    (negative: a signal) for the job it died in and the jobs it never reached."""
    proc = _start(BATCH, script, *(f"{case}:{route}" for case, route in jobs))
    out, err = proc.communicate(timeout=600)
    outs, errs = _by_job(out), _by_job(err)
    results = []
    for case, route in jobs:
        job_out = outs.get(f"{case}:{route}", "")
        last = job_out.rstrip().rsplit("\n", 1)[-1]
        code = int(last.split()[-1]) if last.startswith("=== exit") else proc.returncode
        results.append(((case, route), code, job_out, errs.get(f"{case}:{route}", err[-2000:])))
    return results


def _by_job(text):
    parts = text.split("=== job ")[1:]
    return {p.split("\n", 1)[0]: p.split("\n", 1)[1] if "\n" in p else "" for p in parts}


def _start(script, *args):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.Popen([sys.executable, "-c", script, *args], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _assert_clean_errors(results):
    import re

    for (case, route), code, out, err in results:
        where = f"{case} via {route}: exit code {code}\nstdout: {out}\nstderr (end): {err[-2000:]}"
        assert code >= 0, "killed by a signal (memory corruption): " + where
        assert code == 1, "expected a Python exception: " + where
        assert "fastvi.check.ModelCheckError" in err, where
        assert re.search(CASES[case], err), where
        assert "Raised before any kernel ran" in err, where


def test_size_mistakes_raise_a_clear_error_in_a_fresh_process():
    """Through ``integrate``; through ``Model.check`` in ``test_size_mistakes_raise_every_time``
    (``make test-slow``: one process a case and route, three times)."""
    jobs = [(case, "integrate") for case in CASES]
    jobs.append(("correct", "integrate"))  # the control: the same script runs when nothing is wrong
    results = _run_in_one_process(jobs)
    control = results.pop()
    assert control[1] == 0 and "integrated True" in control[2], control
    _assert_clean_errors(results)


def test_size_mistakes_raise_with_check_false_too():
    """``check=False`` skips the derivative comparison only: before the size guard ran always,
    these ended in a segfault at exit (m too small), a raise then a segfault (transposed
    Jacobian), or a silent success (gradient past n). One fresh process for all (one each,
    three times: ``test_size_mistakes_raise_every_time``, ``make test-slow``)."""
    jobs = [(case, "nocheck") for case in CASES]
    jobs.append(("correct", "nocheck"))
    results = _run_in_one_process(jobs)
    control = results.pop()
    assert control[1] == 0 and "integrated True" in control[2], control
    _assert_clean_errors(results)


def test_event_mistakes_raise_a_clear_error_in_a_fresh_process():
    """Before the event guard an event reading v[n] returned invented crossings (exit 0), one
    writing into v corrupted the recorded velocities silently, and SciPy's ev(t, y) got
    numba's generic typing advice. One fresh process for all, without the model check (the
    guard's own work; with it too: ``test_event_mistakes_raise_with_the_check_too``); the
    correct event is the control."""
    jobs = [(case, "nocheck") for case in EVENT_CASES]
    results = _run_in_one_process(jobs + [("correct", "check")], script=EVENT_SCRIPT)
    control = results.pop()
    assert control[1] == 0 and "integrated True" in control[2], control
    _assert_event_errors(results)


@pytest.mark.slow
def test_event_mistakes_raise_with_the_check_too():
    _assert_event_errors(_run_all([(case, "check") for case in EVENT_CASES], script=EVENT_SCRIPT))


def _assert_event_errors(results):
    import re

    for job, code, out, err in results:
        where = f"{job}: exit code {code}\nstdout: {out}\nstderr (end): {err[-2000:]}"
        assert code >= 0, "killed by a signal: " + where
        assert code == 1 and "fastvi.guards.EventFunctionError" in err, where
        assert re.search(EVENT_CASES[job[0]], err), where


@pytest.mark.slow
def test_size_mistakes_raise_every_time():
    _assert_clean_errors(_run_all([(case, route) for _ in range(3) for case in CASES
                                   for route in ("integrate", "check")]))


# ----------------------------------------------------------------------------- in process
# (safe now: the guarded buffers absorb the bad writes; these pin the details of the messages)
def _V(q, p):
    return p[0] * q[1]


def _dV(q, p, out):
    out[0] = 0.0
    out[1] = p[0]


def _dV_accumulates(q, p, out):  # reads `out` before setting it
    out[0] += 0.0
    out[1] = p[0]


def _dV_writes_q(q, p, out):
    q[0] = 0.0
    out[0] = 0.0
    out[1] = p[0]


def _dV_writes_past_q(q, p, out):
    out[0] = 0.0
    out[1] = p[0]
    r = q[0:3]  # a view longer than q (no bounds checks): r[2] is past the end of q
    r[2] = 1.0


def _circle(q, p, out):
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] - 1.0)


def _circle_jac(q, p, out):
    out[0, 0] = q[0]
    out[0, 1] = q[1]


def _circle_hess_half(q, eta, p, out):  # forgets the off-diagonal entries
    out[0, 0] = eta[0]
    out[1, 1] = eta[0]


def _model(**kw):
    funcs = dict(potential=_V, potential_grad=_dV, constraint=_circle, constraint_jacobian=_circle_jac)
    return fastvi.Model(2, 1, params=(9.81,), mass=np.eye(2), **{**funcs, **kw})


Q, VEL = np.array([0.6, -0.8]), np.array([0.8, 0.6])


def test_updating_out_without_setting_it_is_caught():
    # the kernels reuse their buffers: `+=` on an unset entry adds to a stale value
    with pytest.raises(fastvi.ModelCheckError, match=r"`potential_grad` never wrote entry \[0\] .*"
                                                     r"or only updated it \(`out\[i\] \+= …`\)"):
        _model(potential_grad=_dV_accumulates).check(Q, VEL)


def test_writing_into_an_input_is_caught():
    with pytest.raises(fastvi.ModelCheckError, match="`potential_grad` changed entry 0 of its input `q`") as err:
        _model(potential_grad=_dV_writes_q).check(Q, VEL)
    assert err.value.callback == "potential_grad"
    with pytest.raises(fastvi.ModelCheckError, match="`potential_grad` wrote past the end of its input `q`"):
        _model(potential_grad=_dV_writes_past_q).check(Q, VEL)


def test_unset_matrix_entries_are_named_and_the_error_comes_before_any_derivative_check():
    with pytest.raises(fastvi.ModelCheckError, match=r"`constraint_hessian` never wrote entries \[0, 1\], "
                                                     r"\[1, 0\] of its output \(out shape \(2, 2\)") as err:
        _model(constraint_hessian=_circle_hess_half).check(Q, VEL, raise_on_error=False)
    report = err.value.report
    assert err.value.callbacks == ["constraint_hessian"]
    assert [r.callback for r in report.rows] == ["constraint_hessian"]  # no FD comparison ran
    assert report.rows[0].reference == "declared output shape (2, 2)"


def test_a_correct_model_passes_the_size_check_and_its_cost_is_small():
    model = _model()
    model.check(Q, VEL, n_random=1)  # compiles the callbacks and the guarded evaluator
    model.checked = False
    report = model.check(Q, VEL, n_random=1)  # what integrate runs
    assert report.ok and model.checked
    assert report.wall_time < 0.05, report.wall_time  # measured 2-5 ms on a busy 2-core machine
