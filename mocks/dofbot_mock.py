#!/usr/bin/env python3
"""Mock Yahboom DOFBOT board on a pseudo-terminal (or on a given serial port, via pyserial).

Creates a pty, prints the device path of its slave side on the first line of stdout, and then
behaves like the board of shared/DOFBOT.md: parses `FF FC LEN FUNC payload CHK` frames, moves
six simulated servos at a bounded speed to each commanded raw target over the commanded time,
answers reads (TYPE 0x0A, payload pos_H pos_L 0x30+id, as Yahboom's Arm_Lib.py __parse_data
reads it), pings as --ping says (none: no reply, as the serial Arm_ping_servo never reads one;
status: TYPE 0x38 with one status byte 0xDA, the default; id-status: TYPE 0x38 with id, 0xDA),
version (0x01) and offset state (0x33), and logs every frame it got to a JSONL file.

The servo model and fault counters mirror src/sim/model.rs line for line, so the Rust
in-process simulator (`--sim`) and this mock behave alike. Timing: 10 bit times per byte at
the baud rate, a reply latency (default 3 ms, Yahboom's), moves that last the commanded time or
longer when the speed bound requires.

Faults: --corrupt-every K, --drop-every K, --delay-ms D, --fail-read-servo S,
--fail-read-every K, --disconnect-after N, --stall-servo S, --absent-servo S,
--stale-echo-every K (every k-th read reply comes after a position reply of the next servo,
as an answer to an earlier request would: the host must pass over it by its echo).

Hidden mechanics (model.rs `Mechanics`, for the calibration tests): --mount-offset-deg
d1,..,d6 (servo i reads and moves to the raw of servo angle physical + d_i), --read-noise-counts
N with --noise-seed S (every read adds a uniform integer in -N..N, splitmix64), and
--start-physical-deg a1,..,a6 (the arm starts held by hand at these physical servo angles, 90 =
joint zero, torque off). The state file then also holds `physical_deg`.
The state file (--state) holds the servo positions and targets, rewritten in place after every
frame and at exit (SIGTERM, SIGINT or an injected disconnect): read it once the mock has
exited (a read while it runs may see a rewrite half done).

Both files are written by a thread of their own (`Recorder`): a board has no disk, and a write
that waits on a busy disk (an ext4 journal commit after a build, measured here at 61 ms with a
concurrent `sync` and once above 200 ms in CI) must not hold up a reply. The log is complete
once the mock has exited; while it runs it may lag the link by the disk's delay.
"""
import argparse
import heapq
import json
import os
import queue
import select
import signal
import sys
import threading
import time
import tty

SERVO_COUNT = 6
# DOFBOT.md raw ranges per servo (1..6).
RAW_RANGE = [(900, 3100), (900, 3100), (900, 3100), (900, 3100), (380, 3700), (900, 3100)]
BUS_RAW = (96, 4000)
HOME = [2000, 2000, 2000, 2000, 1487, 2000]  # joint zero (servo 90 deg), gripper 90 deg
VERSION = 1
PING_ALIVE = 0xDA
MAX_LEN = 0x20
# DOFBOT.md scales per servo (1..6): (deg_max, raw_min, raw_max, inverted); ServoScale::DOFBOT.
SCALE = [(180.0, 900, 3100, False), (180.0, 900, 3100, True), (180.0, 900, 3100, True),
         (180.0, 900, 3100, True), (270.0, 380, 3700, False), (180.0, 900, 3100, False)]
MASK64 = (1 << 64) - 1


def checksum(body):
    return sum(body) & 0xFF


def frame(mark, kind, payload):
    body = bytes([len(payload) + 3, kind]) + bytes(payload)
    return bytes([0xFF, mark]) + body + bytes([checksum(body)])


def round_raw(x):
    import math
    return int(math.floor(x + 0.5))


def splitmix64(state):
    """One step of splitmix64; returns (new state, value). Mirrors model.rs splitmix64."""
    state = (state + 0x9E3779B97F4A7C15) & MASK64
    z = state
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
    return state, z ^ (z >> 31)


def raw_at_deg(index, deg):
    """Raw position (not rounded) of servo index (0-based) at servo angle deg; model.rs raw_at_deg."""
    deg_max, lo, hi, inverted = SCALE[index]
    a = deg_max - deg if inverted else deg
    return lo + (hi - lo) * a / deg_max


def deg_at_raw(index, raw):
    """Servo angle of servo index at raw position raw; model.rs deg_at_raw."""
    deg_max, lo, hi, inverted = SCALE[index]
    a = (raw - lo) * deg_max / (hi - lo)
    return deg_max - a if inverted else a


class Decoder:
    """Streaming decoder of host frames; mirrors dofbot_protocol::Decoder."""

    def __init__(self, mark=0xFC):
        self.mark = mark
        self.buf = bytearray()

    def feed(self, data):
        out = []
        for b in data:
            self.buf.append(b)
            while True:
                ev = self._poll()
                if ev is None:
                    break
                out.append(ev)
        return out

    def _poll(self):
        buf = self.buf
        while True:
            i = buf.find(0xFF)
            if i < 0:
                del buf[:]
                return None
            del buf[:i]
            if len(buf) < 2:
                return None
            if buf[1] != self.mark:
                del buf[:1]
                continue
            if len(buf) < 3:
                return None
            n = buf[2]
            if n < 3 or n > MAX_LEN:
                del buf[:1]
                return ("error", "bad length 0x%02X" % n)
            total = n + 2
            if len(buf) < total:
                return None
            body = bytes(buf[2:total - 1])
            if checksum(body) != buf[total - 1]:
                del buf[:1]
                return ("error", "bad checksum")
            kind, payload = buf[3], bytes(buf[4:total - 1])
            raw = bytes(buf[:total])
            del buf[:total]
            return ("frame", kind, payload, raw)


class Servo:
    """One servo's motion; mirrors model.rs ServoModel."""

    def __init__(self, raw):
        self.start, self.target, self.t0, self.dur = float(raw), float(raw), 0.0, 0.0

    def position(self, t):
        if self.dur <= 0.0 or t >= self.t0 + self.dur:
            return self.target
        if t <= self.t0:
            return self.start
        return self.start + (self.target - self.start) * (t - self.t0) / self.dur

    def command(self, target, time_ms, t, max_speed):
        p = self.position(t)
        dur = max(time_ms / 1000.0, abs(target - p) / max_speed)
        self.start, self.target, self.t0, self.dur = p, float(target), t, dur


def in_range(servo_id, raw):
    lo, hi = RAW_RANGE[servo_id - 1]
    return lo <= raw <= hi


class Board:
    """The simulated board; mirrors model.rs Board."""

    def __init__(self, home, args):
        self.servos = [Servo(r) for r in home]
        self.torque = True
        if args.start_physical_deg is not None:
            self.servos = [Servo(raw_at_deg(i, args.start_physical_deg[i] + args.mount_offset_deg[i]))
                           for i in range(SERVO_COUNT)]
            self.torque = False
        self.noise_state = args.noise_seed
        self.a = args
        self.frames = 0
        self.replies = 0
        self.reads = 0
        self.disconnected = False

    def parse(self, f, p):
        """Returns (name, action) or None when the frame is not a valid command."""
        u16 = lambda i: (p[i] << 8) | p[i + 1]
        if 0x11 <= f <= 0x16 and len(p) == 4:
            sid = f - 0x10
            return ("move_servo", [(sid, u16(0))], u16(2)) if in_range(sid, u16(0)) else None
        if f == 0x1D and len(p) == 14:
            moves = [(i + 1, u16(2 * i)) for i in range(SERVO_COUNT)]
            return ("move_all", moves, u16(12)) if all(in_range(s, r) for s, r in moves) else None
        if f == 0x19 and len(p) == 5:
            sid, raw = p[0], u16(1)
            ok = 1 <= sid <= 250 and (in_range(sid, raw) if sid <= SERVO_COUNT else BUS_RAW[0] <= raw <= BUS_RAW[1])
            return ("move_any", [(sid, raw)], u16(3)) if ok else None
        if f == 0x17 and len(p) == 4:
            raw = u16(0)
            ok = all(in_range(s, raw) for s in range(1, SERVO_COUNT + 1))
            return ("move_every", [(s, raw) for s in range(1, SERVO_COUNT + 1)], u16(2)) if ok else None
        if 0x31 <= f <= 0x36 and len(p) == 0:
            return ("read_position", f - 0x30)
        if f == 0x38 and len(p) == 1 and 1 <= p[0] <= 250:
            return ("ping", p[0])
        if f == 0x1A and len(p) == 1 and p[0] in (0, 1):
            return ("torque", p[0] == 1)
        if f == 0x1B and len(p) == 0:
            return ("read_offset_state",)
        if f == 0x01 and len(p) == 0:
            return ("version",)
        if f in (0x18, 0x1C, 0x06) and len(p) == 1:
            return ({0x18: "set_id", 0x1C: "store_mid_offset", 0x06: "buzzer"}[f],)
        if f == 0x02 and len(p) == 3:
            return ("rgb",)
        if f == 0x05 and p == b"\x01":
            return ("reset",)
        return None

    def handle(self, f, p, t):
        """Handles a frame that arrived at t; returns (name, reply bytes, delay) ."""
        if self.disconnected:
            return "ignored", None, 0.0
        self.frames += 1
        cmd = self.parse(f, p)
        reply = self.execute(cmd, t) if cmd else None
        name = cmd[0] if cmd else "invalid"
        if self.a.disconnect_after is not None and self.frames >= self.a.disconnect_after:
            self.disconnected = True
            return name, None, 0.0
        if reply is None:
            return name, None, 0.0
        out = self.send(*reply)
        k = self.a.stale_echo_every
        if out and name == "read_position" and k > 0 and self.reads % k == 0:
            other = cmd[1] % SERVO_COUNT + 1
            raw = round_raw(self.servos[other - 1].position(t))
            stale = frame(0xFB, 0x0A, [raw >> 8, raw & 0xFF, 0x30 + other])
            out = (stale + out[0], out[1] + len(stale) * 10.0 / self.a.baud)
        return (name,) + (out if out else (None, 0.0))

    def execute(self, cmd, t):
        name = cmd[0]
        if name.startswith("move_"):
            for sid, raw in cmd[1]:
                self.move_servo(sid, raw, cmd[2], t)
        elif name == "read_position":
            return self.read(cmd[1], t)
        elif name == "ping":
            sid = cmd[1]
            alive = 1 <= sid <= SERVO_COUNT and self.a.absent_servo != sid
            status = PING_ALIVE if alive else 0
            if self.a.ping == "none":
                return None
            return (0x38, [status] if self.a.ping == "status" else [sid, status])
        elif name == "torque":
            if not cmd[1]:
                for i, s in enumerate(self.servos):
                    self.servos[i] = Servo(s.position(t))
            self.torque = cmd[1]
        elif name == "read_offset_state":
            return (0x33, [1])
        elif name == "version":
            return (0x01, [VERSION])
        return None

    def move_servo(self, sid, raw, time_ms, t):
        if not self.torque or not 1 <= sid <= SERVO_COUNT or self.a.stall_servo == sid:
            return
        self.servos[sid - 1].command(raw, time_ms, t, self.a.max_speed)

    def read(self, sid, t):
        if self.a.absent_servo == sid:
            return None
        self.reads += 1
        k = self.a.fail_read_every
        fail = self.a.fail_read_servo == sid or (k > 0 and self.reads % k == 0)
        if fail:
            raw = 0
        else:
            noise = self.noise()
            raw = max(0, round_raw(self.servos[sid - 1].position(t)) + noise)
        return (0x0A, [raw >> 8, raw & 0xFF, 0x30 + sid])

    def noise(self):
        n = self.a.read_noise_counts
        if n == 0:
            return 0
        self.noise_state, z = splitmix64(self.noise_state)
        return z % (2 * n + 1) - n

    def physical_deg(self, t):
        return [deg_at_raw(i, s.position(t)) - self.a.mount_offset_deg[i]
                for i, s in enumerate(self.servos)]

    def send(self, kind, payload):
        self.replies += 1
        hit = lambda k: k > 0 and self.replies % k == 0
        if hit(self.a.drop_every):
            return None
        b = bytearray(frame(0xFB, kind, payload))
        if hit(self.a.corrupt_every):
            b[-1] ^= 0xFF
        delay = (self.a.reply_latency_ms + self.a.delay_ms) / 1000.0 + len(b) * 10.0 / self.a.baud
        return bytes(b), delay

    def positions(self, t):
        return [round_raw(s.position(t)) for s in self.servos]

    def targets(self):
        return [round_raw(s.target) for s in self.servos]


class PtyLink:
    """The master side of a new pseudo-terminal; the slave's path is what clients open."""

    def __init__(self):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no line discipline before the client configures it
        self.path = os.ttyname(self.slave)

    def fileno(self):
        return self.master

    def read(self):
        return os.read(self.master, 4096)

    def write(self, data):
        os.write(self.master, data)

    def close(self):
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


class SerialLink:
    """An existing port (e.g. one side of a socat pair), opened with pyserial at 115200 8N1."""

    def __init__(self, path, baud):
        import serial
        self.port = serial.Serial(path, int(baud), bytesize=8, parity="N", stopbits=1, timeout=0)
        self.port.reset_input_buffer()
        self.path = path

    def fileno(self):
        return self.port.fileno()

    def read(self):
        return self.port.read(4096)

    def write(self, data):
        self.port.write(data)

    def close(self):
        self.port.close()


def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--port", help="open this existing port with pyserial instead of creating a pty")
    ap.add_argument("--log", help="JSONL file: one line per frame received")
    ap.add_argument("--state", help="JSON file with the servo state, rewritten after every frame")
    ap.add_argument("--initial", help="raw positions r1,..,r6 at start (default: joint zero, gripper 90)")
    ap.add_argument("--baud", type=float, default=115200.0)
    ap.add_argument("--reply-latency-ms", type=float, default=3.0)
    ap.add_argument("--max-speed", type=float, default=3000.0, help="raw counts per second")
    ap.add_argument("--corrupt-every", type=int, default=0)
    ap.add_argument("--drop-every", type=int, default=0)
    ap.add_argument("--delay-ms", type=float, default=0.0)
    ap.add_argument("--fail-read-servo", type=int)
    ap.add_argument("--fail-read-every", type=int, default=0)
    ap.add_argument("--disconnect-after", type=int)
    ap.add_argument("--stall-servo", type=int)
    ap.add_argument("--absent-servo", type=int)
    ap.add_argument("--stale-echo-every", type=int, default=0,
                    help="every k-th read reply comes after a stale reply of the next servo")
    ap.add_argument("--ping", choices=["none", "status", "id-status"], default="status",
                    help="ping reply: none, one status byte, or id and status")
    six = lambda v: [float(x) for x in v.split(",")]
    ap.add_argument("--mount-offset-deg", type=six, default=[0.0] * SERVO_COUNT)
    ap.add_argument("--read-noise-counts", type=int, default=0)
    ap.add_argument("--noise-seed", type=int, default=0)
    ap.add_argument("--start-physical-deg", type=six)
    args = ap.parse_args(argv)
    for name in ("mount_offset_deg", "start_physical_deg"):
        v = getattr(args, name)
        if v is not None and len(v) != SERVO_COUNT:
            ap.error("--%s: need 6 values" % name.replace("_", "-"))
    return args


class Recorder:
    """Writes the frame log (appended, a line per entry) and the state file (rewritten in
    place, the latest state only) on a thread of its own, in the order given; `close` writes
    what is queued and waits for it."""

    def __init__(self, log_path, state_path):
        self.log = open(log_path, "a", buffering=1) if log_path else None
        self.state = open(state_path, "w") if state_path else None
        self.queue = queue.SimpleQueue()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def log_line(self, entry):
        if self.log:
            self.queue.put(("log", json.dumps(entry) + "\n"))

    def write_state(self, state):
        if self.state:
            self.queue.put(("state", json.dumps(state)))

    def close(self):
        self.queue.put(("end", None))
        self.thread.join()
        for f in (self.log, self.state):
            if f:
                f.close()

    def _run(self):
        while True:
            batch = [self.queue.get()]
            while True:
                try:
                    batch.append(self.queue.get_nowait())
                except queue.Empty:
                    break
            # Of the states queued so far only the newest is written (in its place in order).
            newest = max((i for i, (kind, _) in enumerate(batch) if kind == "state"), default=-1)
            for i, (kind, text) in enumerate(batch):
                if kind == "end":
                    return
                if kind == "log":
                    self.log.write(text)
                elif i == newest:
                    self._put_state(text)

    def _put_state(self, text):
        # Rewritten in place, one open file: a new file renamed over the old one freed the old
        # one's blocks on every frame, and on a disk mounted with `discard` that stalled the
        # writer for up to 0.5 s now and then (measured: 519 ms worst in 6,000 such rewrites,
        # 0.2 ms in place).
        self.state.seek(0)
        self.state.write(text)
        self.state.truncate()
        self.state.flush()


def main(argv):
    args = parse_args(argv)
    home = [int(v) for v in args.initial.split(",")] if args.initial else HOME
    if len(home) != SERVO_COUNT:
        sys.exit("--initial: need 6 raw values")
    board = Board(home, args)
    link = SerialLink(args.port, args.baud) if args.port else PtyLink()
    recorder = Recorder(args.log, args.state)
    t0 = time.monotonic()
    clock = lambda: time.monotonic() - t0

    def write_state():
        t = clock()
        recorder.write_state({"t": t, "positions": board.positions(t), "targets": board.targets(),
                              "torque": board.torque, "frames": board.frames,
                              "disconnected": board.disconnected,
                              "physical_deg": board.physical_deg(t)})

    def stop(*_):
        raise SystemExit(0)

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    write_state()
    print(link.path, flush=True)

    decoder = Decoder()
    outbox = []  # heap of (due, seq, bytes)
    seq = 0
    line_free = 0.0
    byte_time = 10.0 / args.baud
    try:
        while not board.disconnected:
            now = clock()
            while outbox and outbox[0][0] <= now:
                link.write(heapq.heappop(outbox)[2])
            wait = max(0.0, outbox[0][0] - now) if outbox else 0.5
            ready, _, _ = select.select([link], [], [], wait)
            if not ready:
                continue
            data = link.read()
            now = clock()
            start = max(now, line_free)
            line_free = start + len(data) * byte_time
            pos = 0
            for b in data:
                pos += 1
                for ev in decoder.feed(bytes([b])):
                    t = start + pos * byte_time
                    if ev[0] == "error":
                        recorder.log_line({"t": t, "error": ev[1]})
                        continue
                    _, kind, payload, raw = ev
                    name, reply, delay = board.handle(kind, payload, t)
                    recorder.log_line({"t": t, "frame": raw.hex(" ").upper(),
                                       "func": "0x%02X" % kind, "cmd": name})
                    if reply is not None:
                        heapq.heappush(outbox, (t + delay, seq, reply))
                        seq += 1
                    write_state()
                    if board.disconnected:
                        break
                if board.disconnected:
                    break
    finally:
        write_state()
        recorder.close()
        link.close()


if __name__ == "__main__":
    main(sys.argv[1:])
