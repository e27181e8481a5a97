//! Benchmark of the host's side of the link: how fast `tribo` takes a run in, through its whole
//! path (the link's reading thread, frame decoding, unpacking, filing into the run store with its
//! fsyncs), and the compression the packed frames give.
//!
//! ```sh
//! cargo run --release -p tribo --example link_bench
//! ```
//!
//! 1. `record`: `tribo run`'s code (`record_run`) against the virtual rig served over a local TCP
//!    connection as fast as it simulates: 20 s unloaded at 20 kS/s × 5 channels (the protocol's
//!    top rate; the pin rings all the way). The rate is the slower of the simulator and the host.
//! 2. `host alone`: the same run's bytes fed to a `Link` from memory and filed into a new run
//!    folder: what the host stack sustains by itself.
//! 3. `pull`: `tribo pull`'s code fetching the whole run again from the rig (a `Pull` from block 0
//!    and the round that checks its end).
//!
//! Compression: each packed block against its protocol v1 `Samples` frame (unpacked counts), and
//! the counts' bytes (2 per count) against the packed data.

use std::net::{TcpListener, TcpStream};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use tribo::link::session::{pull_run, record_run, RunPlan};
use tribo::link::Link;
use tribo_rig::{serve, ServeOptions, VirtualRig, VirtualRigConfig};
use tribo_store::{Run, RunMeta, RunWriter};
use tribo_wire::frame::{decode_one, encode_vec};
use tribo_wire::{Configure, DeviceMsg};

const RATE: u32 = 20_000;
const SECONDS: f32 = 20.0;

/// A virtual rig served on a local TCP connection as fast as it simulates; the link to it.
fn rig_link(rig: VirtualRig) -> (Link, std::thread::JoinHandle<VirtualRig>) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let host = TcpStream::connect(l.local_addr().unwrap()).unwrap();
    let (dev, _) = l.accept().unwrap();
    host.set_nodelay(true).unwrap();
    let server = std::thread::spawn(move || {
        let mut rig = rig;
        let _ = serve(
            &mut rig,
            dev.try_clone().unwrap(),
            dev,
            &ServeOptions {
                speed: f64::INFINITY,
                ..Default::default()
            },
        );
        rig
    });
    let r = host.try_clone().unwrap();
    r.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    (Link::from_stream("bench", r, host), server)
}

fn report(what: &str, frames: u64, bytes: u64, samples: u64, wall: f64) {
    println!(
        "  {what:<10} {frames} frames, {:.1} MB, {samples} samples in {wall:.2} s: {:.0} frames/s, {:.2} MB/s, \
         {:.0} kS/s of five channels ({:.1}× the top rate live)",
        bytes as f64 / 1e6,
        frames as f64 / wall,
        bytes as f64 / wall / 1e6,
        samples as f64 / wall / 1e3,
        samples as f64 / wall / RATE as f64
    );
}

fn main() {
    let store = tempfile::tempdir().unwrap();
    let cfg = VirtualRigConfig {
        load_n: 0.0,
        ..Default::default()
    };
    println!(
        "== link: {SECONDS} s unloaded at {RATE} S/s × 5 channels, virtual rig over local TCP, as fast as it goes =="
    );

    // 1. record_run, end to end.
    let (mut link, server) = rig_link(VirtualRig::new(cfg.clone()).unwrap());
    let info = link.hello().unwrap();
    let mut c = Configure::real_rig(0.0);
    c.sample_rate_hz = RATE;
    c.max_duration_s = SECONDS;
    let plan = RunPlan::new(c);
    let t0 = Instant::now();
    let mut t_first: Option<Instant> = None;
    let o = record_run(
        &mut link,
        &info,
        store.path(),
        &plan,
        &AtomicBool::new(false),
        &mut |p| {
            if let tribo::link::session::Progress::Started { .. } = p {
                t_first = Some(Instant::now());
            }
        },
    )
    .unwrap();
    let wall = t_first.map_or(t0, |t| t).elapsed().as_secs_f64();
    let stats = link.stats();
    drop(link);
    let _ = server.join();
    let run = &o.run;
    assert!(run.is_complete(), "{}", run.completeness().summary());
    let samples: u64 = run.blocks().map(|b| b.samples() as u64).sum();
    // (Includes the host fit, CSV export and catalog of `finish`: the recording's whole cost.)
    report("record", stats.frames_in, stats.bytes_in, samples, wall);

    // Compression of what was stored.
    let frames: Vec<Vec<u8>> = run.frames().iter().map(|f| f.to_vec()).collect();
    let (mut packed_frames, mut v1_frames, mut counts, mut packed_data) = (0usize, 0usize, 0, 0);
    for f in &frames {
        if let DeviceMsg::Packed(p) = decode_one::<DeviceMsg>(f).unwrap().msg {
            let b = p.unpack().unwrap();
            packed_frames += f.len();
            packed_data += p.data.len();
            counts += b.counts.len() * 2;
            v1_frames += encode_vec(0, &DeviceMsg::Samples(b)).unwrap().len();
        }
    }
    println!(
        "  compression: {} blocks, frames {:.2} MB packed vs {:.2} MB as v1 Samples frames (ratio {:.2}); counts \
         {:.2} MB vs {:.2} MB packed data (ratio {:.2}, {:.2} bits a count)",
        run.block_count(),
        packed_frames as f64 / 1e6,
        v1_frames as f64 / 1e6,
        v1_frames as f64 / packed_frames as f64,
        counts as f64 / 1e6,
        packed_data as f64 / 1e6,
        counts as f64 / packed_data as f64,
        16.0 * packed_data as f64 / counts as f64
    );

    // 2. The host stack alone: the run's bytes from memory, through a Link, into a run folder.
    let bytes: Vec<u8> = frames.concat();
    let n = bytes.len();
    let mut link = Link::from_stream("memory", std::io::Cursor::new(bytes), std::io::sink());
    let header = match decode_one::<DeviceMsg>(&frames[0]).unwrap().msg {
        DeviceMsg::RunStarted(h) => h,
        _ => unreachable!(),
    };
    let mut w = RunWriter::create(store.path(), RunMeta::new(header.config)).unwrap();
    let t0 = Instant::now();
    let mut got = 0u64;
    while let Ok(Some(f)) = link.next(Duration::from_secs(5)) {
        w.file_frame(&f.raw).unwrap();
        got += 1;
        if matches!(f.msg(), DeviceMsg::RunEnded(_)) {
            break;
        }
    }
    let wall = t0.elapsed().as_secs_f64();
    assert!(w.is_complete());
    report("host alone", got, n as u64, samples, wall);

    // 3. pull_run: the whole run fetched again from the rig, into a new store.
    let store2 = tempfile::tempdir().unwrap();
    let mut rig = VirtualRig::new(cfg).unwrap();
    {
        // The same run taken again with the cable out, then pulled.
        let (mut link, server) = rig_link(rig);
        link.hello().unwrap();
        for m in [
            tribo_wire::HostMsg::Configure(c),
            tribo_wire::HostMsg::HeaterOff,
            tribo_wire::HostMsg::Arm,
            tribo_wire::HostMsg::Release,
        ] {
            link.command(m).unwrap();
        }
        drop(link);
        rig = server.join().unwrap();
        rig.set_connected(false);
        let end = rig.now_us() + (SECONDS as u64 + 1) * 1_000_000;
        rig.advance_to(end);
        rig.set_connected(true);
    }
    let (mut link, server) = rig_link(rig);
    let info = link.hello().unwrap();
    while link.drain(Duration::from_millis(200)).unwrap() > 0 {}
    let before = link.stats();
    let t0 = Instant::now();
    let o = pull_run(&mut link, &info, store2.path(), None, false, &mut |_| {}).unwrap();
    let wall = t0.elapsed().as_secs_f64();
    let after = link.stats();
    drop(link);
    let _ = server.join();
    assert!(o.run.is_complete(), "{}", o.run.completeness().summary());
    let samples: u64 = o.run.blocks().map(|b| b.samples() as u64).sum();
    report(
        "pull",
        after.frames_in - before.frames_in,
        after.bytes_in - before.bytes_in,
        samples,
        wall,
    );
    let _ = Run::open(o.run.dir()).unwrap();
}
