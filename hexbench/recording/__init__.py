"""Episode recordings: every evaluated episode as an MCAP file (Foxglove) and a Rerun .rrd.

    rec = make_episode_recorder(out_dir, episode_id, meta)
    rec.on_reset(env); rec.on_step(env, obs, action, reward, info) ...; files = rec.on_end(row)
    rec.abort()   # on error: remove temporaries, leave nothing under a final name

See docs/recording.md for the file contents, rates and precision.
"""

from hexbench.recording.recorder import EpisodeRecorder, RecordingConfig, make_episode_recorder

__all__ = ["EpisodeRecorder", "RecordingConfig", "make_episode_recorder"]
