"""Reads scalars back from TensorBoard event files (to test what training logged)."""

from pathlib import Path


def scalars(folder: Path, tag: str) -> list[float]:
    from tensorboardX.proto import event_pb2

    values = []
    for path in sorted(Path(folder).glob("events.out.tfevents.*")):
        data = path.read_bytes()
        offset = 0
        while offset < len(data):
            length = int.from_bytes(data[offset:offset + 8], "little")
            event = event_pb2.Event.FromString(data[offset + 12: offset + 12 + length])
            offset += 12 + length + 4
            values += [v.simple_value for v in event.summary.value if v.tag == tag]
    return values
