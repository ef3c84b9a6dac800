"""Pictures of one recorded run of the cell, made from its bag (ROS-free: rosbags reads it).

The executor's state stream gives the errors over time and the executed contact path
(the perceived principal contact in the object frame); the wrist camera's frames come
from the image topic at the moments the state stream marks.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

STATE_TOPIC = "/executor/state"
IMAGE_TOPIC = "/arm2/camera/image_raw"


@dataclass
class RunRecord:
    """The active part of an executor run, one row per executor/state message."""
    times: np.ndarray            # s, header stamps (sim time), from the run's start
    start: float                 # s, header stamp of the run's first state
    primitive_index: np.ndarray
    kinds: np.ndarray            # 0 rotation, 1 translation
    steps: list[str]
    contact_error: np.ndarray    # m
    angle_error: np.ndarray      # rad
    contacts: np.ndarray         # (n, 3) m, perceived principal contact in the object frame

    def marks(self, limit: int = 6) -> list[tuple[float, str]]:
        """(time, label) of the run's start, each push's start and its end: where to look."""
        marks = [(0.0, "start")]
        for i in range(1, len(self.steps)):
            if self.steps[i] == "EXECUTE" and self.steps[i - 1] != "EXECUTE":
                kind = "rotation" if self.kinds[i] == 0 else "translation"
                marks.append((float(self.times[i]), f"push, primitive {self.primitive_index[i] + 1} ({kind})"))
        marks = marks[:limit - 1] + [(float(self.times[-1]), "end")]
        return marks


def _stamp(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def read_run(bag: Path) -> RunRecord:
    """The last executor run in the bag."""
    from rosbags.rosbag2 import Reader

    from dmg_bringup.bag import typestore

    store = typestore()
    runs: list[list] = []
    was_active = False
    with Reader(bag) as reader:
        connections = [c for c in reader.connections if c.topic == STATE_TOPIC]
        for connection, _, data in reader.messages(connections=connections):
            msg = store.deserialize_cdr(data, connection.msgtype)
            if msg.active and not was_active:
                runs.append([])
            if msg.active:
                runs[-1].append(msg)
            was_active = msg.active
    states = runs[-1] if runs else []
    if not states:
        raise ValueError(f"'{bag}' has no active {STATE_TOPIC} messages: no run was recorded")
    times = np.array([_stamp(m.header) for m in states])
    return RunRecord(times - times[0], float(times[0]), np.array([m.primitive_index for m in states]),
                     np.array([m.kind for m in states]), [m.step_name for m in states],
                     np.array([m.contact_error for m in states]), np.array([m.angle_error for m in states]),
                     np.array([[m.contact.x, m.contact.y, m.contact.z] for m in states]))


def camera_frames(bag: Path, moments: list[float], topic: str = IMAGE_TOPIC) -> list[np.ndarray | None]:
    """The image whose stamp is nearest each moment (absolute stamps [s]); None where there is none."""
    from rosbags.rosbag2 import Reader

    from dmg_bringup.bag import typestore

    store = typestore()
    best: list[tuple[float, np.ndarray | None]] = [(np.inf, None) for _ in moments]
    with Reader(bag) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        for connection, _, data in reader.messages(connections=connections):
            msg = store.deserialize_cdr(data, connection.msgtype)
            stamp = _stamp(msg.header)
            for i, moment in enumerate(moments):
                if abs(stamp - moment) < best[i][0]:
                    image = np.asarray(msg.data, dtype=np.uint8).reshape(msg.height, msg.width, -1)
                    best[i] = (abs(stamp - moment), image.copy())
    return [image for _, image in best]


def plot_errors(record: RunRecord, output: Path) -> Path:
    """Remaining contact displacement and angle over time, pushes shaded, primitives marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(9, 5.5), dpi=110)
    top.plot(record.times, record.contact_error * 1000, color="tab:red")
    bottom.plot(record.times, np.degrees(record.angle_error), color="tab:blue")
    pushing = np.array([step == "EXECUTE" for step in record.steps])
    changes = np.flatnonzero(np.diff(record.primitive_index)) + 1
    for axes in (top, bottom):
        axes.fill_between(record.times, 0, 1, where=pushing, transform=axes.get_xaxis_transform(),
                          color="0.85", label="pushing")
        for change in changes:
            axes.axvline(record.times[change], color="0.4", linestyle="--", linewidth=0.8)
        axes.grid(alpha=0.3)
    top.set_ylabel("contact error [mm]")
    bottom.set_ylabel("angle error [deg]")
    bottom.set_xlabel("time since the run started [s, simulated]")
    top.legend(loc="upper right")
    top.set_title("remaining error of the current primitive (dashed: next primitive)")
    figure.tight_layout()
    figure.savefig(output)
    plt.close(figure)
    return output


def frame_sheet(frames: list[np.ndarray | None], labels: list[str], output: Path) -> Path:
    """The wrist-camera frames side by side (three per row), each with its label."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = min(3, len(frames))
    rows = -(-len(frames) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 3.4 * rows), dpi=110, squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, frame, label in zip(axes.flat, frames, labels):
        if frame is not None:
            ax.imshow(frame)
        ax.set_title(label, fontsize=9)
    figure.tight_layout()
    figure.savefig(output)
    plt.close(figure)
    return output
