"""The player's model without Qt and without channels: logs merged in log-time order from their
summaries, read a segment at a time; the cut with undo; topics left out; the play clock with
seeks, speed changes and steps both ways; files opened and closed while it plays; the event
history; and new logs written from a selection (cut, merge), read back with the mcap library.

The player sends into a list here; what consumer processes receive is tested in
test_log_robots.py (miro log play) and test_qt_logplayer.py (the window).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path

import Miro
import pytest
from eventlog_helpers import T0, write_log
from loopback import eventually
from mcap.reader import make_reader

from miro_gen.eventlog.edit import write_selection
from miro_gen.eventlog.fileset import Event, FileSet, after, at_time
from miro_gen.eventlog.logfile import Cancelled
from miro_gen.eventlog.player import Player, Row
from miro_gen.eventlog.reader import LogError

A, B = ("robotA", "ExampleEvent"), ("robotB", "ExampleEvent")
MS = 1_000_000


def ident(e: Event | Row) -> tuple[str, int]:
    return e.topic.domain, e.sequence if isinstance(e, Row) else e.message.sequence


@pytest.fixture
def two_robots(tmp_path: Path) -> tuple[Path, Path]:
    """robotA every 10 ms from 0, robotB every 10 ms from 5 ms, 40 each, in chunks of 8 events;
    robotB's event 10 shares its log time with robotA's event 11 (a tie)."""
    a = write_log(tmp_path / "a.mcap", [("robotA", n, 10 * n) for n in range(40)], chunk_every=8)
    b_events = [("robotB", n, 10 * n + 5) for n in range(40)]
    b_events[10] = ("robotB", 10, 110)
    b = write_log(tmp_path / "b.mcap", b_events, chunk_every=8)
    return a, b


@pytest.fixture
def files(two_robots: tuple[Path, Path]) -> Iterator[FileSet]:
    fs = FileSet()
    for path in two_robots:
        fs.add(str(path))
    yield fs
    fs.close()


class Sent:
    """What a player sends, in order, with a way to wait for it."""

    def __init__(self) -> None:
        self.events: list[Event] = []
        self.lock = threading.Lock()

    def __call__(self, event: Event) -> None:
        with self.lock:
            self.events.append(event)

    def ids(self) -> list[tuple[str, int]]:
        with self.lock:
            return [ident(e) for e in self.events]

    def wait(self, count: int) -> list[tuple[str, int]]:
        eventually(lambda: len(self.events) >= count)
        return self.ids()


@pytest.fixture
def player(files: FileSet) -> Iterator[tuple[Player, Sent]]:
    sent = Sent()
    p = Player(files, sent, rate=1000.0)
    p.start()
    yield p, sent
    p.close()


# ---- opening -------------------------------------------------------------------------------------


def test_a_finished_log_opens_from_its_summary_without_reading_its_data(
    files: FileSet,
) -> None:
    a, b = files.files
    assert a.indexed and b.indexed and not a.warnings
    assert len(a.segments) == 5  # 40 events in chunks of 8
    assert files.segments_read == 0  # nothing but the summaries so far
    assert files.count == 80
    assert [(t.name, t.events) for t in files.topics()] == [(A, 40), (B, 40)]
    assert files.span() == (T0, T0 + 395 * MS)
    assert files.domains() == ["robotA", "robotB"]
    density = files.density(10, *files.span())
    assert round(sum(density[A])) == 40 and round(sum(density[B])) == 40


def test_events_merge_in_one_order_forward_backward_and_from_anywhere(files: FileSet) -> None:
    forward = list(files.forward())
    assert len(forward) == 80
    assert [e.key for e in forward] == sorted(e.key for e in forward)
    assert [ident(e) for e in forward[:4]] == [
        ("robotA", 0),
        ("robotB", 0),
        ("robotA", 1),
        ("robotB", 1),
    ]
    tie = [ident(e) for e in forward if e.log_time == T0 + 110 * MS]
    assert tie == [("robotA", 11), ("robotB", 10)]  # the same time: file order
    middle = forward[37]
    assert list(files.forward(middle.key)) == forward[37:]
    assert list(files.forward(after(middle.key))) == forward[38:]
    assert list(files.backward(middle.key)) == forward[36::-1]
    assert list(files.forward(at_time(T0 + 110 * MS)))[0:2] == forward[21:23]


def test_only_the_segments_played_are_read_and_each_once(two_robots: tuple[Path, Path]) -> None:
    fs = FileSet(cache_segments=16)  # all ten kept: a segment read twice would be a fault
    for path in two_robots:
        fs.add(str(path))
    late = list(fs.forward(at_time(T0 + 300 * MS)))
    assert len(late) == 20 and fs.segments_read == 4  # the last two chunks of each file
    assert list(fs.forward(at_time(T0 + 300 * MS))) == late and fs.segments_read == 4
    assert ident(next(fs.backward(late[0].key))) == ("robotB", 29)  # a step back
    eventually(lambda: fs.segments_read == 6)  # the chunks before it, read ahead
    assert ident(next(fs.backward(at_time(T0 + 235 * MS)))) == ("robotA", 23)
    eventually(lambda: fs.segments_read == 8)  # and the ones before those
    assert [ident(e) for e in fs.backward(at_time(T0 + 235 * MS))][-1] == ("robotA", 0)
    assert fs.segments_read == 10
    fs.close()


def test_the_cut_with_undo_and_topics_left_out(files: FileSet) -> None:
    changes: list[str] = []
    files.listeners.append(changes.append)
    full = files.span()
    assert files.cut_front(T0 + 100 * MS) and files.cut_back(T0 + 200 * MS)
    assert files.cut == (T0 + 100 * MS, T0 + 200 * MS) and files.is_cut
    assert not files.cut_back(T0 + 50 * MS)  # would leave nothing
    assert files.undo_cut() and files.cut == (T0 + 100 * MS, full[1])
    assert files.undo_cut() and files.cut == full
    assert not files.undo_cut()
    files.cut_front(T0 + 300 * MS)
    files.undo_all()
    assert files.cut == full and not files.can_undo
    files.exclude(B)
    assert files.excluded == {B}
    files.exclude(B, False)
    assert files.excluded == frozenset()
    assert changes == ["cut"] * 5 + ["cut", "excluded", "excluded"]


def test_an_unfinished_log_is_read_through_with_progress_and_can_be_cancelled(
    tmp_path: Path,
) -> None:
    path = write_log(
        tmp_path / "killed.mcap",
        [("robotA", n, n) for n in range(3000)],
        chunk_every=100,
        finish=False,
    )
    fs = FileSet()
    with pytest.raises(Cancelled):
        fs.add(str(path), lambda fraction: False)
    assert fs.files == []
    seen: list[float] = []
    log = fs.add(str(path), lambda fraction: seen.append(fraction) or True)
    assert not log.indexed and seen and seen[-1] == 1.0
    assert any("unfinished" in w for w in log.warnings)
    assert log.fault is None and len(log.segments) == 30
    assert [e.message.sequence for e in fs.forward()] == list(range(3000))
    fs.close()


def test_a_damaged_chunk_ends_the_scan_the_events_before_it_are_used(tmp_path: Path) -> None:
    path = write_log(
        tmp_path / "damaged.mcap",
        [("robotA", n, n) for n in range(40)],
        chunk_every=10,
        finish=False,
    )
    fs = FileSet()
    clean = fs.add(str(path))
    third = clean.segments[2].offset
    fs.close()
    data = bytearray(path.read_bytes())
    data[third + 60] ^= 0xFF  # inside the third chunk's compressed data
    path.write_bytes(bytes(data))
    fs = FileSet()
    log = fs.add(str(path))
    assert log.fault is not None and "chunk 3" in log.fault and "damaged" in log.fault
    assert [e.message.sequence for e in fs.forward()] == list(range(20))
    fs.close()
    for name, content, why in (
        ("text.mcap", b"not a log\n", "not an MCAP file"),
        ("missing.mcap", None, "cannot open"),
    ):
        if content is not None:
            (tmp_path / name).write_bytes(content)
        with pytest.raises(LogError, match=why):
            FileSet().add(str(tmp_path / name))


def test_a_log_whose_times_lie_in_the_future_says_so(tmp_path: Path) -> None:
    import time

    ahead = (time.time_ns() - T0) // MS + 3_600_000  # an hour from now
    path = write_log(tmp_path / "future.mcap", [("robotA", 0, 0), ("robotA", 1, ahead)])
    fs = FileSet()
    log = fs.add(str(path))
    assert any("in the future" in w for w in log.warnings)
    with pytest.raises(LogError, match="open already"):
        fs.add(str(path))
    fs.close()


# ---- the player ----------------------------------------------------------------------------------


def test_plays_everything_in_order_and_stops_at_the_end(
    files: FileSet, player: tuple[Player, Sent]
) -> None:
    p, sent = player
    p.play()
    assert p.ended.wait(30)
    assert sent.ids() == [ident(e) for e in files.forward()]
    assert p.at_end and not p.playing and p.sent == 80
    assert [r.key for r in p.history.rows()] == [e.key for e in sent.events]
    p.play()  # at the end, play starts again at the start of the cut
    eventually(lambda: p.sent == 160)


def test_sent_counts_an_event_being_sent_when_pause_returns(files: FileSet) -> None:
    """Before: `sent` grew after the send, outside the lock, so an event the play thread had
    taken but not finished sending when pause() came was counted after pause() had returned;
    a window's (or the terminal's) count read at the pause was one short of what the
    consumers then received (a rare failure of the GUI's and the terminal's pause tests).
    Now an event is counted when it is taken: what pause() leaves counted is what goes out."""
    inside, release = threading.Event(), threading.Event()
    sent = Sent()

    def send(event: Event) -> None:
        sent(event)
        if len(sent.events) == 3:
            inside.set()
            release.wait(30)

    p = Player(files, send, rate=1000.0)
    p.start()
    try:
        p.play()
        assert inside.wait(30)  # the third event is being sent
        p.pause()
        counted = p.sent
        release.set()
        p.close(30)  # (its thread joined: the send finished and nothing more was taken)
        assert counted == p.sent == len(sent.events) == 3, (counted, p.sent)
    finally:
        release.set()
        p.close()


def test_next_and_prev_step_through_events_both_ways(player: tuple[Player, Sent]) -> None:
    p, sent = player
    for _ in range(3):
        p.next()
    assert sent.wait(3) == [("robotA", 0), ("robotB", 0), ("robotA", 1)]
    p.prev()  # the event before the one last sent
    assert sent.wait(4)[3] == ("robotB", 0)
    p.prev()
    assert sent.wait(5)[4] == ("robotA", 0)
    p.prev()  # at the start: nothing before
    p.next()
    assert sent.wait(6)[5] == ("robotA", 0)
    assert p.paused and p.log_now() == T0


def test_seek_moves_the_position_playing_or_paused(
    files: FileSet, player: tuple[Player, Sent]
) -> None:
    p, sent = player
    p.seek(T0 + 200 * MS)
    p.next()
    assert sent.wait(1) == [("robotA", 20)]
    p.prev()  # after a seek, the event just before the position
    assert sent.wait(2)[1] == ("robotB", 19)
    p.seek(T0 + 352 * MS)
    p.play()
    assert p.ended.wait(30)
    assert sent.ids()[2:] == [ident(e) for e in files.forward(at_time(T0 + 352 * MS))]
    p.seek(T0 - 10**9)  # kept inside the cut
    assert p.log_now() == T0


def test_the_speed_changes_while_playing_along_the_dial_s_steps(
    player: tuple[Player, Sent],
) -> None:
    p, sent = player
    p.set_rate(1e-6)  # a log second in 11 days: nothing after the first event comes
    p.play()
    assert sent.wait(1) == [("robotA", 0)]
    epoch = p.clock().epoch
    assert p.faster(1) == 1 / 16 and p.faster(-1) == 1 / 16  # the slowest step
    p.set_rate(3.0)
    assert p.faster(1) == 4.0 and p.faster(-1) == 2.0 and p.faster(-1) == 1.0
    p.set_rate(32.0)
    assert p.faster(1) == 32.0
    p.set_rate(1000.0)
    assert p.ended.wait(30) and p.sent == 80  # played on at the new speed, nothing skipped
    clock = p.clock()
    assert clock.rate == 1000.0 and clock.paused and clock.epoch == epoch  # no jump
    with pytest.raises(ValueError):
        p.set_rate(0)


def test_excluded_topics_are_skipped_while_playing_and_stepping(
    files: FileSet, player: tuple[Player, Sent]
) -> None:
    p, sent = player
    files.exclude(B)
    p.next()
    p.next()
    assert sent.wait(2) == [("robotA", 0), ("robotA", 1)]
    p.play()
    assert p.ended.wait(30)
    assert [d for d, _ in sent.ids()] == ["robotA"] * 40
    assert all(e.name == A for e in p.history.rows())


def test_files_open_and_close_while_it_plays(two_robots: tuple[Path, Path]) -> None:
    fs = FileSet()
    fs.add(str(two_robots[0]))
    sent = Sent()
    p = Player(fs, sent, rate=1000.0)
    p.start()
    try:
        p.next()
        assert sent.wait(1) == [("robotA", 0)]
        fs.add(str(two_robots[1]))  # robotB's events from here on
        p.play()
        assert p.ended.wait(30)
        assert sent.ids()[1:3] == [("robotB", 0), ("robotA", 1)]
        assert len(sent.ids()) == 80
        p.seek(T0)
        fs.remove(str(two_robots[0]))
        p.play()
        assert p.ended.wait(30)
        assert {d for d, _ in sent.ids()[80:]} == {"robotB"} and len(sent.ids()) == 120
    finally:
        p.close()
        fs.close()


def test_a_cut_keeps_the_player_inside_it(files: FileSet, player: tuple[Player, Sent]) -> None:
    p, sent = player
    files.cut_front(T0 + 300 * MS)
    files.cut_back(T0 + 320 * MS)
    assert p.log_now() == T0 + 300 * MS
    p.play()
    assert p.ended.wait(30)
    assert sent.ids() == [
        ("robotA", 30),
        ("robotB", 30),
        ("robotA", 31),
        ("robotB", 31),
        ("robotA", 32),
    ]
    p.stop()
    assert p.log_now() == T0 + 300 * MS and p.paused


def test_the_history_holds_the_events_before_the_position(
    files: FileSet, player: tuple[Player, Sent]
) -> None:
    p, _ = player
    p.history.set_length(5)
    p.seek(T0 + 100 * MS)
    rows = p.history.rows()
    assert [ident(e) for e in rows] == [
        ("robotB", 7),
        ("robotA", 8),
        ("robotB", 8),
        ("robotA", 9),
        ("robotB", 9),
    ]
    p.history.set_length(7)  # more: older ones are read
    assert [ident(e) for e in p.history.rows()][:2] == [("robotB", 6), ("robotA", 7)]
    p.history.set_length(2)
    assert [ident(e) for e in p.history.rows()] == [("robotA", 9), ("robotB", 9)]
    with pytest.raises(ValueError):
        p.history.set_length(0)
    p.seek_to(rows[1])  # a row of the event list: it is the next one played
    p.next()
    eventually(lambda: p.sent == 1)
    assert ident(p.history.rows()[-1]) == ("robotA", 8)


# ---- new logs from a selection -------------------------------------------------------------------


def read_back(path: Path) -> list[tuple[str, int, int]]:
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.chunk_indexes and summary.statistics is not None
        return [(ch.topic, m.sequence, m.log_time) for _, ch, m in reader.iter_messages()]


def test_a_cut_or_a_merge_writes_exactly_the_selected_events(
    files: FileSet, two_robots: tuple[Path, Path], tmp_path: Path
) -> None:
    before = [p.read_bytes() for p in two_robots]
    out = tmp_path / "cut.mcap"
    n = write_selection(files, str(out), T0 + 100 * MS, T0 + 200 * MS, lambda name: name == A)
    assert n == 11
    assert read_back(out) == [("robotA/ExampleEvent", s, T0 + s * 10 * MS) for s in range(10, 21)]
    merged = tmp_path / "merged.mcap"
    assert write_selection(files, str(merged)) == 80
    expected = [
        (f"{d}/ExampleEvent", s, e.log_time) for e in files.forward() for d, s in [ident(e)]
    ]
    assert read_back(merged) == expected
    with open(merged, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert sorted(c.topic for c in summary.channels.values()) == [
        "robotA/ExampleEvent",
        "robotB/ExampleEvent",
    ]
    assert len(summary.schemas) == 1  # one type: one schema
    [schema] = summary.schemas.values()
    assert (
        schema.name == "Miro::ExampleEventIDL"
        and schema.data.decode() == Miro.ExampleEventIDL._data_schema
    )
    assert [p.read_bytes() for p in two_robots] == before
    # Merging a merged file with one of its inputs: one channel per topic still.
    again = FileSet()
    again.add(str(merged))
    again.add(str(two_robots[0]))
    both = tmp_path / "both.mcap"
    assert write_selection(again, str(both)) == 120
    with open(both, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and len(summary.channels) == 2
    again.close()


def test_a_plot_keeps_the_extremes_of_each_span(files: FileSet) -> None:
    def counter(e: Event) -> float:
        return float(Miro.ExampleEventIDL.deserialize(e.message.data).counter)

    all_points = files.series(A, counter, *files.span(), buckets=1000)
    assert [v for _, v in all_points] == [float(n) for n in range(40)]
    few = files.series(A, counter, *files.span(), buckets=4)
    assert len(few) == 8 and min(v for _, v in few) == 0 and max(v for _, v in few) == 39
    before = files.segments_read
    files.series(A, counter, T0, T0 + 50 * MS, buckets=10)
    assert files.segments_read - before <= 1  # only what holds those times


def test_a_damaged_chunk_of_an_indexed_log_stops_the_player_there(tmp_path: Path) -> None:
    path = write_log(tmp_path / "bad.mcap", [("robotA", n, n) for n in range(30)], chunk_every=10)
    fs = FileSet()
    second = fs.add(str(path)).segments[1]
    fs.close()
    data = bytearray(path.read_bytes())
    data[second.offset + 60] ^= 0xFF  # inside the second chunk's compressed data
    path.write_bytes(bytes(data))
    fs = FileSet()
    assert fs.add(str(path)).fault is None  # the summary is sound: opened without reading
    sent = Sent()
    p = Player(fs, sent, rate=1000.0)
    p.start()
    try:
        p.play()
        assert p.ended.wait(30)
        assert sent.ids() == [("robotA", n) for n in range(10)]  # the first chunk, then the fault
        assert p.error is not None and "chunk 2" in str(p.error) and "damaged" in str(p.error)
        assert getattr(p.error, "path", None) == str(path)
        p.seek(T0 + 25 * MS)  # past it: plays on
        p.play()
        eventually(lambda: len(sent.ids()) == 15)
        assert p.error is None
    finally:
        p.close()
        fs.close()
