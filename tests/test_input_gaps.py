"""The live loop's count of missing frames from a source's clock (``rtseg.live.input_gaps``)
when the clock gives absurd values: a timestamp of 1e308 (a finite JSON number a Rokoko
payload may carry) or a jump past the float range is a clock jump - no missing frames,
no period learned from it, no exception - and the count goes on afterwards."""

from __future__ import annotations

import numpy as np

from rtseg.live.config import from_dict
from rtseg.live.input_gaps import MAX_STEP_S, InputGaps
from rtseg.live.pipeline import Pipeline
from rtseg.simulators.synth.motion import synthesize

P = 1 / 60


def test_absurd_clock_steps_count_no_missing_frames_and_teach_no_period():
    g = InputGaps(max_gap_frames=12)
    times = [k * P for k in range(20)]
    assert [g.step(None, None, t)[0] for t in times] == [0] * 20
    for t in (1e308, -1e308, 1e308, times[-1] + MAX_STEP_S + 1.0):
        assert g.step(None, None, t)[0] == 0
    g.step(None, None, 100.0)                 # a clock segment of its own: back to normal
    assert g.step(None, None, 100.0 + P)[0] == 0
    assert g.step(None, None, 100.0 + 6 * P)[0] == 4          # 4 frames lost
    assert abs(g._src_period - P) < 1e-9


def test_a_frame_stamped_1e308_is_processed_like_any_other():
    take = synthesize("idle:2,walk:2", frame_rate=60.0, seed=1).take
    pipe = Pipeline(take.joint_names, take.parents, take.space, 60.0, from_dict({}))
    for i in range(take.n_frames):
        t = 1e308 if i == 90 else (-1e308 if i == 91 else i * P)
        pipe.process(i, take.quats[i], np.ones(take.n_joints, bool), None, i * P, 0, t)
    st = pipe.stats
    assert st.fed + st.calibration_frames == take.n_frames and st.gap_frames == 0
