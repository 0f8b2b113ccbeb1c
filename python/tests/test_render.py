"""secure.Overlay and secure.VideoWriter: the overlay `secure render` draws, from Python."""
import os
import shutil

import numpy as np
import pytest

import secure


def grey(h=240, w=320):
    return np.full((h, w, 3), 100, dtype=np.uint8)


def test_overlay_draws_a_copy_with_band_border_and_panel():
    overlay = secure.Overlay(title="SECURE", max_steps=50)
    frame = grey()
    out = overlay.draw(frame, step=1, h=0.25, status="safe_after_resampling", intervened=True)
    assert out.shape == frame.shape and out.dtype == np.uint8
    assert (frame == 100).all(), "draw() must not change its input"
    assert (out[:10] != 100).any(), "no top band"
    assert (out[-10:] != 100).any(), "no panel"
    left = out[120, 1]  # the border on the left edge: orange for an intervention
    assert left[0] > 200 and 90 < left[1] < 200 and left[2] < 80
    calm = secure.Overlay(panel=False).draw(frame, step=1, h=0.25, status="safe")
    assert (calm[120, 1] == 100).all() and (calm[-3, 160] == 100).all()


def test_overlay_is_deterministic_and_reset_starts_a_new_episode():
    def episode(overlay):
        out = None
        for t in range(8):
            out = overlay.draw(grey(), step=t, h=0.1 * t - 0.3, status="safe" if t else "")
        return out

    a, b = secure.Overlay(max_steps=10), secure.Overlay(max_steps=10)
    first = episode(a)
    np.testing.assert_array_equal(first, episode(b))
    a.reset()
    np.testing.assert_array_equal(episode(a), first)


def test_overlay_rejects_bad_frames_and_values():
    overlay = secure.Overlay()
    with pytest.raises(TypeError, match="uint8"):
        overlay.draw(grey().astype(np.float32), step=0)
    with pytest.raises(TypeError, match="uint8"):
        overlay.draw([[1, 2, 3]], step=0)
    with pytest.raises(ValueError, match=r"got \(240, 320, 4\)"):
        overlay.draw(np.zeros((240, 320, 4), np.uint8), step=0)
    with pytest.raises(ValueError, match="32 x 24"):
        overlay.draw(grey(24, 32), step=0)
    with pytest.raises(ValueError, match="status"):
        overlay.draw(grey(), step=1, status="fine")
    with pytest.raises(ValueError, match="finite"):
        overlay.draw(grey(), step=1, h=float("nan"))
    with pytest.raises(ValueError, match="max_steps = -1"):
        secure.Overlay(max_steps=-1)


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg is not installed")
def test_video_writer_writes_on_success_and_discards_on_error(tmp_path):
    path = str(tmp_path / "v.mp4")
    overlay = secure.Overlay(max_steps=5)
    with secure.VideoWriter(path, 320, 240, fps=10) as video:
        for t in range(5):
            video.write(overlay.draw(grey(), step=t, h=0.5 - 0.1 * t))
    assert video.finished and video.frames == 5
    assert os.path.getsize(path) > 0
    with open(path, "rb") as f:
        assert f.read(12)[4:8] == b"ftyp"  # an MP4 container
    before = open(path, "rb").read()
    with pytest.raises(RuntimeError, match="boom"):
        with secure.VideoWriter(path, 320, 240) as video:
            video.write(grey())
            raise RuntimeError("boom")
    assert open(path, "rb").read() == before, "a failed video must leave the old file"
    assert sorted(os.listdir(tmp_path)) == ["v.mp4"], "no scratch file may be left"
    with pytest.raises(ValueError, match="320 x 240|size"):
        secure.VideoWriter(str(tmp_path / "w.mp4"), 320, 240).write(grey(120, 160))
    with pytest.raises(RuntimeError, match="finished"):
        video.write(grey())
    with pytest.raises(ValueError):
        secure.VideoWriter(str(tmp_path), 320, 240)  # a directory


def test_objects_made_without_init_raise_instead_of_crashing():
    with pytest.raises(TypeError, match="not initialised"):
        secure.Overlay.__new__(secure.Overlay).draw(grey(), step=0)
    with pytest.raises(TypeError, match="not initialised"):
        secure.VideoWriter.__new__(secure.VideoWriter).discard()
