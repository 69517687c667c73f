"""Whether two recordings of lockstep runs hold the same samples, bit for bit: for each topic
(default /joint_states, /contact_wrench, /impact_report), the serialized payloads compared
stamp by stamp (header stamp; /impact_report in order). A refactoring that must not change
the output is checked by recording `impact-arm run --mode lockstep` before and after:

    python bench/same_recordings.py runs/before.mcap runs/after.mcap

Two runs stop at slightly different periods (the nodes are stopped after the last impact), so
only the stamps both hold are compared; the last of them may be the period answering the
controller's zero command on exit, which differs between two runs of the same code too.
Exit status 1 when any other payload differs."""

import sys

from mcap.reader import make_reader

TOPICS = ('/joint_states', '/contact_wrench', '/impact_report')


def payloads(path, topic):
    """{header stamp [ns]: payload} (stamped topics) or {index: payload}. The stamp follows
    the 4-byte CDR header (little endian: int32 sec, uint32 nanosec)."""
    out = {}
    with open(path, 'rb') as f:
        for i, (_, _, message) in enumerate(make_reader(f).iter_messages(topics=[topic])):
            data = message.data
            key = (
                i
                if topic == '/impact_report'
                else int.from_bytes(data[4:8], 'little', signed=True) * 1_000_000_000
                + int.from_bytes(data[8:12], 'little')
            )
            out.setdefault(key, data)
    return out


def main(argv) -> int:
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    a_path, b_path, topics = argv[0], argv[1], argv[2:] or TOPICS
    bad = 0
    for topic in topics:
        a, b = payloads(a_path, topic), payloads(b_path, topic)
        common = sorted(set(a) & set(b))
        differ = [k for k in common if a[k] != b[k]]
        last = max(common) if common else None
        bad += len([k for k in differ if k != last])
        print(
            f'{topic}: {len(a)} / {len(b)} samples, {len(common)} in common, '
            f'{len(common) - len(differ)} identical'
            + (f', {len(differ)} different' if differ else '')
            + (' (only the last common one)' if differ == [last] else '')
        )
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
