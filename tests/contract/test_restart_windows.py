"""One cutting of restarted windows (``validation.restart_windows``) for every restarted free run: the single DOF's
held-out validation, a structure's, the hybrid's gap and the posterior's likelihood windows, each with its own
settings. A window is a stretch of the record a free run is restarted over from the measured state at its first
sample; it must lie inside the record (a run past the last sample would be scored against nothing)."""

import numpy as np
import pytest

from negstiff.inference.steps.validation import restart_windows


@pytest.mark.parametrize(
    "n, start, window_s, fs",
    [(15360, 12288, 2.0, 512.0), (5000, 0, 0.125, 512.0), (1000, 999, 2.0, 512.0), (4096, 100, 0.01, 1000.0)],
)
def test_the_single_dofs_windows_are_whole_consecutive_and_inside_the_record(n, start, window_s, fs):
    w = int(round(window_s * fs))
    win = restart_windows(n, fs, window_s, start=start)
    assert len(win) == (n - start) // w  # every whole window of the held-out part, none cut short
    assert win.length == win.step == w
    if len(win):
        assert win.starts[0] == start and np.all(np.diff(win.starts) == w) and win.index.max() <= n - 1


def test_a_structures_windows_end_on_the_next_ones_start_and_hold_eight_samples_at_least():
    # a structure's input is linear between samples: each window spans L + 1 samples, the next starts at its last
    win = restart_windows(6000, 512.0, 0.25, start=4800, extra=1, min_step=8)
    L = 128
    assert win.length == L + 1 and np.all(win.starts == np.arange(4800, 6000 - L, L))
    assert np.all(win.index[:-1, -1] == win.starts[1:]) and win.index.max() <= 5999
    assert restart_windows(100, 512.0, 0.001, extra=1, min_step=8).length == 9  # 0.5 sample asked: 8 given


def test_at_most_max_windows_spread_evenly_over_the_whole_record():
    # the posterior's windows: every regime the record visits seen, the first and the last window kept
    every = restart_windows(20480, 512.0, 0.125)
    some = restart_windows(20480, 512.0, 0.125, max_windows=16)
    assert len(every) == 20480 // 64 and len(some) == 16
    assert some.starts[0] == 0 and some.starts[-1] == every.starts[-1]
    assert set(some.starts) <= set(every.starts)
    gaps = np.diff(some.starts) / 64
    assert gaps.max() - gaps.min() <= 1  # even, to one window


def test_measured_segments_and_start_states_of_one_channel_and_of_several():
    z = np.arange(40.0)
    v = -np.arange(40.0)
    win = restart_windows(40, 1.0, 8.0, start=4)
    assert np.array_equal(win.measured(z)[1], np.arange(12.0, 20.0))
    assert np.array_equal(win.start_states(z, v)[2], [20.0, -20.0])
    zz, vv = np.stack([z, 10 * z]), np.stack([v, 10 * v])
    assert win.measured(zz).shape == (4, 2, 8)
    assert np.array_equal(win.start_states(zz, vv)[0], [4.0, 40.0, -4.0, -40.0])


def test_windows_at_chosen_starts_cut_and_run_like_the_stepped_ones():
    # the discrepancy's windows before each episode of an effect: chosen starts, one length; cut alike, and run by
    # simulate_windows to the same numbers as the evenly stepped windows with those starts
    from negstiff import Rig, from_arrays
    from negstiff.inference.steps.validation import RestartWindows, simulate_windows
    from negstiff.models import AS_BUILT

    win = RestartWindows.at([3, 17, 30], 5)
    assert len(win) == 3 and win.length == win.step == 5
    assert np.array_equal(win.measured(np.arange(40.0))[1], np.arange(17.0, 22.0))
    r = Rig(seed=2).random(duration=4.0)
    rec = from_arrays(r.columns["base_acc"], r.columns["z"], r.fs, mass=float(r.meta["mass"]))
    zs, v, _, _ = rec.states("state")
    stepped = restart_windows(rec.n, rec.fs, 0.5)
    chosen = RestartWindows.at(stepped.starts, stepped.length)
    model = AS_BUILT.lsq_cubic()
    a, b = (simulate_windows(model, rec, w, zs, v) for w in (stepped, chosen))
    assert np.array_equal(a.z, b.z)
