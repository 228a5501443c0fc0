"""Drawings of the scenes, animations (GIF) and trajectory plots of a Result."""

import pickle

import matplotlib
import matplotlib.animation
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

import fastvi
from fastvi import animation
from fastvi.drawing import Drawing, cartesian
from fastvi.results import Result
from fastvi.scenes import SCENES


@pytest.fixture(scope="module")
def dp_run(double_pendulum, dp_start):
    """2 s of the double pendulum, a sample every 0.01 s (201 samples)."""
    return fastvi.integrate(double_pendulum, *dp_start, h=0.01, n_steps=200)


@pytest.fixture(scope="module")
def sp_run():
    """1 s of a spherical pendulum with dense output, a sample every 10 steps."""
    model = fastvi.scenes.spherical_pendulum()
    q0, v0 = model.initial_state(1.0, 0.0, 0.0, 2.0)
    return fastvi.integrate(model, q0, v0, h=0.01, n_steps=100, save_every=10, dense_output=True)


def _frames(path):
    with Image.open(path) as im:
        return im.n_frames, im.size


def _fresh_figure():
    fig = Figure()
    FigureCanvasAgg(fig)
    return fig


# ------------------------------------------------------------------ the drawings of the scenes
def test_double_pendulum_points_agree_with_the_angles():
    l1, l2, th1, th2 = 0.7, 1.3, 2.1, -0.4
    model = fastvi.scenes.double_pendulum(l1=l1, l2=l2)
    q, _ = model.initial_state(th1, th2)
    x1, y1 = l1 * np.sin(th1), -l1 * np.cos(th1)
    x2, y2 = x1 + l2 * np.sin(th2), y1 - l2 * np.cos(th2)
    np.testing.assert_allclose(model.drawing.positions(q), [[0, 0], [x1, y1], [x2, y2]], atol=1e-15)
    assert model.drawing.pivots == (0,)
    assert sorted(map(tuple, model.drawing.links.tolist())) == [(0, 1), (1, 2)]


def test_bars_keep_their_lengths_along_a_run(dp_run):
    pts = dp_run.drawing.trace(dp_run.q, dp_run.t)  # (K, 3, 2)
    assert pts.shape == (dp_run.t.size, 3, 2)
    for (a, b), length in zip(dp_run.drawing.links, (1.0, 1.0)):
        np.testing.assert_allclose(np.linalg.norm(pts[:, b] - pts[:, a], axis=1), length, atol=1e-12)
    np.testing.assert_array_equal(pts[:, 0], 0.0)


def test_kapitza_drawing_follows_the_moving_pivot():
    a, omega, l = 0.05, 150.0, 0.8
    model = fastvi.scenes.kapitza_pendulum(l=l, a=a, omega=omega)
    assert model.drawing.time_dependent
    for t in (0.0, 0.013, 0.4):
        q, _ = model.initial_state(0.3, t0=t)
        pivot, bob = model.drawing.positions(q, t)
        np.testing.assert_allclose(pivot, [0.0, a * np.cos(omega * t)], atol=1e-15)
        assert np.linalg.norm(bob - pivot) == pytest.approx(l, abs=1e-14)


def test_rotary_rod_slider_draws_the_rod_and_the_slider():
    model = fastvi.scenes.rotary_rod_slider(l=2.0)
    theta, r = 0.6, 1.3
    o, tip, slider = model.drawing.positions(np.array([theta, r, theta]))
    np.testing.assert_allclose(o, 0.0)
    np.testing.assert_allclose(tip, 2.0 * np.array([np.cos(theta), np.sin(theta)]), atol=1e-15)
    np.testing.assert_allclose(slider, r * np.array([np.cos(theta), np.sin(theta)]), atol=1e-15)


#: the rigid-body scenes (fastvi.bodies): in space, drawn from their mechanism
RIGID = ("heavy_top", "lagrange_top", "fast_top", "spatial_slider_crank", "bricard",
         "flyball_governor", "body_chain")


def _start(name, model):
    if name in RIGID:
        return model.initial_state()[0]
    if name in ("chain", "tree", "ladder"):
        N = {"chain": 5, "tree": 10, "ladder": 8}[name]
        return model.initial_state(np.linspace(0.2, 0.9, N))[0]
    if name == "closed_chain":
        return model.initial_state()[0]
    if name in ("double_pendulum", "spherical_pendulum"):
        return model.initial_state(0.4, 0.3)[0]
    if name == "triple_pendulum":
        return model.initial_state(0.4, 0.3, 0.2)[0]
    return model.initial_state(0.4)[0]


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_scene_has_a_drawing_whose_bars_are_its_links(name):
    model = SCENES[name](N=5) if name == "chain" else SCENES[name]()
    drawing = model.drawing
    assert isinstance(drawing, Drawing)
    assert drawing.dim == (3 if name == "spherical_pendulum" or name in RIGID else 2)
    q = _start(name, model)
    P = drawing.check(q, 0.0)
    assert P >= 2 and drawing.links.size and drawing.pivots
    pts = drawing.positions(q)
    # a Cartesian scene's constraints are its bars' lengths: at a consistent state every bar
    # between two points is as long as the constraint says, so no bar joins the wrong points
    if model.m and name not in ("rotary_rod_slider", "slider_crank", "kapitza_pendulum") + RIGID:
        lengths = np.linalg.norm(pts[drawing.links[:, 1]] - pts[drawing.links[:, 0]], axis=1)
        assert np.all(lengths > 0.1) and np.all(lengths < 3.0), lengths
        assert np.max(np.abs(model.constraint_value(q))) < 1e-12


def test_drawing_fields_are_checked():
    pts = lambda q: np.zeros((2, 2))  # noqa: E731
    with pytest.raises(ValueError, match="`dim`"):
        Drawing(4, pts, [(0, 1)])
    with pytest.raises(ValueError, match="`links`"):
        Drawing(2, pts, [(0, 1, 2)])
    with pytest.raises(ValueError, match="`frames`.*dim=3"):
        Drawing(2, pts, [(0, 1)], frames=lambda q: None)
    with pytest.raises(ValueError, match="`drawing.links` names point 5"):
        Drawing(2, pts, [(0, 5)]).check(np.zeros(2))
    with pytest.raises(ValueError, match=r"`drawing.labels` must have one entry per point \(P = 2\)"):
        Drawing(2, pts, [(0, 1)], labels=("a",)).check(np.zeros(2))
    with pytest.raises(ValueError, match=r"must return a \(P, 3\) array"):
        Drawing(3, pts, [(0, 1)]).check(np.zeros(2))


def test_cartesian_puts_fixed_points_around_the_masses():
    d = cartesian(4, [(0, 1), (1, 2), (2, 3)], before=[(0.0, 0.0)], after=[(5.0, 0.0)])
    np.testing.assert_array_equal(d.positions(np.array([1.0, 2.0, 3.0, 4.0])),
                                  [[0, 0], [1, 2], [3, 4], [5, 0]])
    assert d.pivots == (0, 3)


# ------------------------------------------------------------------ travel
def test_a_scene_drawing_survives_pickle_save_and_load(dp_run, tmp_path):
    q = dp_run.q[-1]
    back = pickle.loads(pickle.dumps(dp_run))
    np.testing.assert_array_equal(back.drawing.positions(q), dp_run.drawing.positions(q))
    dp_run.save(tmp_path / "run.npz")
    loaded = Result.load(tmp_path / "run.npz")
    np.testing.assert_array_equal(loaded.drawing.positions(q), dp_run.drawing.positions(q))
    # built from the scene's own arguments, not the defaults
    model = fastvi.scenes.double_pendulum(l1=0.5)
    again = pickle.loads(pickle.dumps(model.drawing))
    np.testing.assert_array_equal(again.positions(model.initial_state(1.0, 0.0)[0])[1],
                                  [0.5 * np.sin(1.0), -0.5 * np.cos(1.0)])


def test_other_drawings_do_not_travel(dp_run, tmp_path):
    own = Drawing(2, lambda q: np.reshape(q, (2, 2)), [(0, 1)])
    r = Result(**{**dp_run.__dict__, "drawing": own})
    assert pickle.loads(pickle.dumps(r)).drawing is None
    r.save(tmp_path / "own.npz")
    assert Result.load(tmp_path / "own.npz").drawing is None


# ------------------------------------------------------------------ animations
def test_gif_of_a_planar_scene_has_the_frames_asked_for(dp_run, tmp_path):
    before = matplotlib.get_backend()
    path = dp_run.animate(tmp_path / "dp.gif", fps=12, duration=1.0)
    assert matplotlib.get_backend() == before
    count, (width, height) = _frames(path)
    assert count == 12 and 300 < width < 600 and height > 200
    with Image.open(path) as im:  # GIF delays are whole centiseconds: 1000/12 ms -> 80 or 90
        assert abs(im.info["duration"] - 1000 / 12) <= 10
    # a frame every 50 saved samples: samples 0, 50, 100, 150, 200
    assert _frames(dp_run.animate(tmp_path / "every.gif", every=50, trail=None))[0] == 5


def test_gif_of_the_spherical_pendulum_is_drawn_in_space(sp_run, tmp_path):
    fig = _fresh_figure()
    path = animation.render(sp_run, tmp_path / "sp.gif", fig, fps=10, duration=0.7)
    assert _frames(path)[0] == 7
    assert fig.axes[0].name == "3d"


@pytest.mark.parametrize("which", ["dp", "sp"])
def test_axis_limits_hold_every_point_of_the_run(which, dp_run, sp_run, tmp_path):
    run = dp_run if which == "dp" else sp_run
    fig = _fresh_figure()
    animation.render(run, tmp_path / "lim.gif", fig, fps=5, duration=0.4)
    ax = fig.axes[0]
    pts = run.drawing.trace(run.q, run.t).reshape(-1, run.drawing.dim)
    bounds = [ax.get_xlim(), ax.get_ylim()] + ([ax.get_zlim()] if run.drawing.dim == 3 else [])
    for k, (lo, hi) in enumerate(bounds):
        assert lo < pts[:, k].min() and pts[:, k].max() < hi, (k, lo, hi)
    # the dense output between the saved samples too (the bob's lowest point may fall there)
    if which == "sp":
        dense = run.sol(np.linspace(run.t[0], run.t[-1], 501))[0]
        assert ax.get_zlim()[0] < dense[:, 2].min()


def _rod_frame(q):
    """A body frame at the bob: d3 along the rod towards the pivot, d1 horizontal."""
    d3 = -q / np.linalg.norm(q)
    d1 = np.cross([0.0, 0.0, 1.0], d3)
    d1 /= np.linalg.norm(d1)
    return q[None, :], np.column_stack((d1, np.cross(d3, d1), d3))[None]


def test_body_frames_fit_in_the_view(sp_run, tmp_path):
    drawing = Drawing(3, lambda q: np.array([np.zeros(3), q]), [(0, 1)], frames=_rod_frame,
                      frame_size=0.6)
    fig = _fresh_figure()
    path = animation.render(sp_run, tmp_path / "frames.gif", fig, drawing=drawing, fps=5,
                            duration=1.0)
    assert _frames(path)[0] == 5
    ax = fig.axes[0]
    t, q, _ = animation.frame_samples(sp_run, fps=5, duration=1.0, every=None)
    tips = np.array([o[0] + 0.6 * R[0][:, k] for o, R in map(_rod_frame, q) for k in range(3)])
    for k, (lo, hi) in enumerate([ax.get_xlim(), ax.get_ylim(), ax.get_zlim()]):
        assert lo < tips[:, k].min() and tips[:, k].max() < hi, k
    wrong = Drawing(3, drawing.points, [(0, 1)], frames=lambda q: (q[None], np.eye(3)))
    with pytest.raises(ValueError, match=r"origins \(B, 3\) and R \(B, 3, 3\)"):
        wrong.check(q[0])


def test_frames_come_from_the_dense_output_or_the_nearest_sample(dp_run, sp_run):
    t, q, speed = animation.frame_samples(sp_run, fps=10, duration=1.0, every=None)
    np.testing.assert_allclose(t, np.linspace(0.0, 1.0, 10))
    np.testing.assert_array_equal(q, sp_run.sol(t)[0])
    assert speed == pytest.approx(1.0)
    t, q, speed = animation.frame_samples(dp_run, fps=4, duration=1.0, every=None)
    np.testing.assert_allclose(t, [0.0, 2 / 3, 4 / 3, 2.0], atol=0.006)  # the samples nearest
    assert all(np.any(np.all(dp_run.q == row, axis=1)) for row in q)  # saved samples, not blends
    assert speed == pytest.approx(2.0)


@pytest.mark.parametrize("which", ["dp", "sp"])
def test_frozen_background_draws_the_same_picture(which, dp_run, sp_run, tmp_path, monkeypatch):
    run = dp_run if which == "dp" else sp_run
    fast = run.animate(tmp_path / "fast.gif", fps=4, duration=1.0)
    monkeypatch.setattr(animation, "_freeze_background", lambda *args: None)
    slow = run.animate(tmp_path / "slow.gif", fps=4, duration=1.0)
    with Image.open(fast) as a, Image.open(slow) as b:
        for k in range(4):
            a.seek(k)
            b.seek(k)
            diff = np.abs(np.asarray(a.convert("RGB"), float) - np.asarray(b.convert("RGB"), float))
            assert np.count_nonzero(diff.max(axis=2) > 40) < 20, k


def test_animation_errors_say_what_to_do(dp_run, tmp_path, monkeypatch):
    bare = Result(**{**dp_run.__dict__, "drawing": None})
    with pytest.raises(ValueError, match=r"'double_pendulum' has no drawing.*`drawing=`.*`model.drawing = "):
        bare.animate(tmp_path / "x.gif")
    with pytest.raises(ValueError, match=r"`model.drawing = "):
        bare.plot_trajectory()
    with pytest.raises(TypeError, match="fastvi.drawing.Drawing"):
        dp_run.animate(tmp_path / "x.gif", drawing="pendulum")
    with pytest.raises(ValueError, match=r"\.gif .*\.mp4"):
        dp_run.animate(tmp_path / "x.avi")
    monkeypatch.setattr(matplotlib.animation.FFMpegWriter, "isAvailable", classmethod(lambda cls: False))
    with pytest.raises(RuntimeError, match="install ffmpeg.*\\.gif"):
        dp_run.animate(tmp_path / "x.mp4")
    with pytest.raises(ValueError, match="`duration`.*`every`.*not both"):
        dp_run.animate(tmp_path / "x.gif", duration=1.0, every=3)
    with pytest.raises(ValueError, match="`fps`"):
        dp_run.animate(tmp_path / "x.gif", fps=0)
    with pytest.raises(ValueError, match="`trail_points`.*P = 3"):
        dp_run.animate(tmp_path / "x.gif", duration=0.1, trail_points=[7])


@pytest.mark.skipif(not matplotlib.animation.FFMpegWriter.isAvailable(), reason="no ffmpeg")
def test_mp4_is_written_by_ffmpeg(dp_run, tmp_path):
    path = dp_run.animate(tmp_path / "dp.mp4", fps=10, duration=0.5)
    assert path.stat().st_size > 1000


def test_a_loaded_result_animates_with_a_drawing_passed(dp_run, tmp_path):
    bare = Result(**{**dp_run.__dict__, "drawing": None})
    path = bare.animate(tmp_path / "passed.gif", fps=5, duration=0.4,
                        drawing=fastvi.scenes.double_pendulum().drawing)
    assert _frames(path)[0] == 2


def test_progress_reports_the_frames(dp_run, tmp_path, capsys):
    dp_run.animate(tmp_path / "p.gif", fps=5, duration=0.6, progress=True)
    assert "fastvi animate: 3/3 frames" in capsys.readouterr().err


# ------------------------------------------------------------------ trajectory plots
def test_plot_trajectory_in_the_plane_and_in_space(dp_run, sp_run, tmp_path):
    fig = dp_run.plot_trajectory(path=tmp_path / "dp.png")
    assert (tmp_path / "dp.png").stat().st_size > 1000
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels == ["m1", "m2"]  # the moving points, named by the drawing
    path_line = fig.axes[0].get_lines()[-1]
    np.testing.assert_array_equal(path_line.get_xdata(), dp_run.q[:, 2])
    fig3 = sp_run.plot_trajectory(points=[1], path=tmp_path / "sp.png")
    assert fig3.axes[0].name == "3d"
    with pytest.raises(ValueError, match="`points` holds indices outside 0…1"):
        sp_run.plot_trajectory(points=[2], path=tmp_path / "bad.png")
