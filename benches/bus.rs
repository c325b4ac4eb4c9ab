//! Bus speed: 0x1D frame throughput and read-back latency over a pseudo-terminal against the
//! Python mock board (which emulates 115200 baud and the board's 3 ms reply latency), and the
//! same through the in-process simulator. Needs POLISHBOT_PYTHON (the test venv's python).
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use dofbot_protocol::servo::ServoId;
use dofbot_protocol::Pose;
use polishbot::bus::{Bus, BusConfig, Journal, SerialTransport, Transport};
use polishbot::sim::{SimArm, SimOptions};

const BATCH: u64 = 100;

/// The mock process, killed (by its handle) when dropped, also on a panic.
struct MockGuard(Child);

impl Drop for MockGuard {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn start_mock() -> Option<(MockGuard, String)> {
    let python = std::env::var_os("POLISHBOT_PYTHON")?;
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/mocks/dofbot_mock.py");
    let mut child = Command::new(python)
        .arg(script)
        .stdout(Stdio::piped())
        .spawn()
        .ok()?;
    let mut line = String::new();
    BufReader::new(child.stdout.take()?)
        .read_line(&mut line)
        .ok()?;
    Some((MockGuard(child), line.trim().to_string()))
}

/// Sends BATCH motion frames back to back, then one read whose reply can only come after the
/// board has taken every frame before it.
fn burst<T: Transport>(bus: &mut Bus<T>, poses: &[Pose]) -> Duration {
    let start = Instant::now();
    for (i, p) in poses.iter().enumerate() {
        bus.send_motion(i as u64, *p, 20).unwrap();
    }
    bus.read_raw(ServoId::ALL[0]).unwrap();
    start.elapsed()
}

fn poses() -> Vec<Pose> {
    (0..BATCH)
        .map(|k| Pose::new([1500 + k as u16, 2000, 2000, 2000, 1487, 2000]).unwrap())
        .collect()
}

fn bench_bus(c: &mut Criterion) {
    // Back-to-back frames, and a read timeout long enough for the read behind a burst to wait
    // for the line (100 x 19 bytes at 115200 baud is 165 ms) instead of retrying.
    let cfg = BusConfig {
        frame_gap_ms: 0.0,
        read_timeout_ms: 2000.0,
        attempts: 1,
        ..BusConfig::default()
    };
    let poses = poses();
    let mut g = c.benchmark_group("bus");
    g.sample_size(10).measurement_time(Duration::from_secs(6));
    match start_mock() {
        Some((_mock, path)) => {
            let mut bus = Bus::connect(
                SerialTransport::open(&path).unwrap(),
                cfg.clone(),
                Journal::none(),
            )
            .unwrap();
            g.throughput(Throughput::Elements(BATCH + 1));
            g.bench_function("pty_mock_motion_frames", |b| {
                b.iter_custom(|n| (0..n).map(|_| burst(&mut bus, &poses)).sum())
            });
            // Let the line drain before timing single reads on an idle bus.
            std::thread::sleep(Duration::from_millis(500));
            g.throughput(Throughput::Elements(1));
            g.bench_function("pty_mock_read_latency", |b| {
                b.iter(|| bus.read_raw(ServoId::ALL[2]).unwrap())
            });
        }
        None => eprintln!("bus bench: POLISHBOT_PYTHON not set, skipping the pty benches"),
    }
    let arm = SimArm::new(&SimOptions::default(), &cfg.servo_map).unwrap();
    let mut bus = Bus::connect(arm.transport(), cfg, Journal::none()).unwrap();
    g.throughput(Throughput::Elements(BATCH + 1));
    g.bench_function("sim_motion_frames_wall", |b| {
        b.iter_custom(|n| (0..n).map(|_| burst(&mut bus, &poses)).sum())
    });
    g.finish();
}

criterion_group!(benches, bench_bus);
criterion_main!(benches);
