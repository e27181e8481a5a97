//! Benchmark of the whole-run work: block compression ratio on simulated noisy records, the
//! rig-side cost per sample of compressing and storing, and the link's sustained rate.
//!
//! ```sh
//! cargo run --release -p tribo-rig --example wholerun_bench            # everything
//! cargo run --release -p tribo-rig --example wholerun_bench -- ratio   # one part: ratio | cost | link
//! # Instructions per sample of the rig-side path (host x86-64 instructions, not Cortex-M7 cycles):
//! cargo build --release -p tribo-rig --example wholerun_bench
//! valgrind --tool=callgrind --callgrind-out-file=/tmp/cg.out --toggle-collect='*rig_side*' \
//!     target/release/examples/wholerun_bench cost
//! callgrind_annotate /tmp/cg.out | head -20    # total Ir / the samples printed = instructions/sample
//! ```

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::time::{Duration, Instant};
use tribo_firmware::hal::{FlashGeometry, RunFlash};
use tribo_firmware::runstore::memflash::MemFlash;
use tribo_firmware::runstore::{RunStore, BOARD_RING_BYTES, MAX_RUN_BLOCKS};
use tribo_physics::sensor::{generate, RecordSpec, SensorModel};
use tribo_physics::{FrictionLaw, Method, Model, Rig};
use tribo_rig::{serve, ServeOptions, VirtualRig, VirtualRigConfig};
use tribo_wire::codec::encode;
use tribo_wire::frame::{decode_one, encode_vec, Decoder, Encoder, MAX_FRAME};
use tribo_wire::*;

fn main() {
    let what = std::env::args().nth(1).unwrap_or_default();
    match what.as_str() {
        "ratio" => ratio(),
        "cost" => cost(),
        "link" => link(),
        "" => {
            ratio();
            cost();
            link();
        }
        other => {
            eprintln!("unknown part `{other}`: ratio, cost or link (none: all three)");
            std::process::exit(2);
        }
    }
}

// ------------------------------------------------------------------------------------------------
// Compression ratio
// ------------------------------------------------------------------------------------------------

/// Sizes of a set of blocks, raw and packed, overall and by channel.
#[derive(Default)]
struct Sizes {
    samples: usize,
    counts: usize,
    /// Packed data bytes (codec output).
    packed: usize,
    /// v1 `Samples` frames and v2 `Packed` frames, bytes.
    frames_v1: usize,
    frames_v2: usize,
    /// Packed bytes of each channel coded alone.
    by_channel: [usize; CHANNELS],
    channels: ChannelSet,
}

impl Sizes {
    fn add(&mut self, b: &SampleBlock) {
        let n = b.samples();
        self.samples += n;
        self.counts += b.counts.len();
        self.channels = b.channels;
        let p = PackedBlock::pack(b).expect("blocks pack");
        self.packed += p.data.len();
        self.frames_v1 += encode_vec(1_000_000, &DeviceMsg::Samples(b.clone()))
            .unwrap()
            .len();
        self.frames_v2 += encode_vec(1_000_000, &DeviceMsg::Packed(p)).unwrap().len();
        for (i, c) in b.channels.iter().enumerate() {
            let lane: Vec<u16> = b.channel(c).collect();
            let mut out = [0u8; 2 * BLOCK_LEN + 1];
            self.by_channel[i] += encode(&lane, n, 1, &mut out).unwrap();
        }
    }

    fn print(&self, what: &str) {
        let raw = 2 * self.counts;
        println!(
            "{what}: {} samples × {} channels",
            self.samples,
            self.channels.len()
        );
        println!(
            "  counts: {:.2} bits/count, ratio {:.2} (raw {} B, packed {} B)",
            8.0 * self.packed as f64 / self.counts as f64,
            raw as f64 / self.packed as f64,
            raw,
            self.packed
        );
        println!(
            "  frames: v1 {} B, v2 {} B: ratio {:.2}, {:.1} B per v2 block",
            self.frames_v1,
            self.frames_v2,
            self.frames_v1 as f64 / self.frames_v2 as f64,
            self.frames_v2 as f64 / self.samples as f64 * BLOCK_LEN as f64
        );
        let names: Vec<String> = self
            .channels
            .iter()
            .enumerate()
            .map(|(i, c)| {
                format!(
                    "{} {:.2}",
                    c.name(),
                    8.0 * self.by_channel[i] as f64 / self.samples as f64
                )
            })
            .collect();
        println!(
            "  bits/count by channel (coded alone): {}",
            names.join(", ")
        );
    }
}

/// A record of `tribo-physics` through its acquisition chain (16-bit ADC, white noise on x and v,
/// the charge amplifier's low-pass and noise on F), turned back into ADC counts and blocks of the
/// displacement, velocity and force channels.
fn physics_blocks(load_n: f64, law: FrictionLaw, seconds: f64) -> Vec<SampleBlock> {
    let rig = Rig::new(0.04, 1150.0, load_n.max(1e-3)).unwrap();
    let model = Model::new(law).with_apparatus_damping(0.0011);
    let spec = RecordSpec {
        rig,
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: seconds,
        rate_hz: 10_000.0,
    };
    let sensor = SensorModel::default();
    let rec = generate(&spec, &model, Method::default(), Some(&sensor)).unwrap();
    let count = |v: f64, range: f64| {
        let step = 2.0 * range / 65536.0;
        ((v / step).round() + 32768.0).clamp(0.0, 65535.0) as u16
    };
    let ft = rec.ft.clone().unwrap_or_else(|| vec![0.0; rec.len()]);
    let channels = ChannelSet::EMPTY
        .with(Channel::Displacement)
        .with(Channel::Velocity)
        .with(Channel::Force);
    let mut blocks = vec![];
    for (k, start) in (0..rec.len()).step_by(BLOCK_LEN).enumerate() {
        let mut counts = Counts::default();
        let end = (start + BLOCK_LEN).min(rec.len());
        for ((x, v), f) in rec.x[start..end]
            .iter()
            .zip(&rec.v[start..end])
            .zip(&ft[start..end])
        {
            counts.push(count(*x, sensor.disp_range_m)).unwrap();
            counts.push(count(*v, sensor.vel_range_m_s)).unwrap();
            counts.push(count(*f, sensor.force_range_n)).unwrap();
        }
        blocks.push(SampleBlock {
            run_id: 1,
            block: k as u32,
            first_sample: start as u32,
            t_us: start as u64 * 100,
            channels,
            ecr_range: 0,
            log10_ecr_ohm: 7.0,
            temp_c: 25.0,
            counts,
        });
    }
    blocks
}

/// The blocks of a run of the virtual rig (all five channels at 10 kS/s).
fn rig_blocks(cfg: VirtualRigConfig, load_n: f32, seconds: f32) -> Vec<SampleBlock> {
    let mut rig = VirtualRig::new(cfg).unwrap();
    let mut c = Configure::real_rig(load_n);
    c.max_duration_s = seconds;
    let mut seq = 0;
    let mut send = |rig: &mut VirtualRig, m: HostMsg| {
        seq += 1;
        rig.input(&encode_vec(seq, &m).unwrap());
    };
    send(&mut rig, HostMsg::Configure(c));
    send(&mut rig, HostMsg::Arm);
    rig.advance_to(300_000);
    send(&mut rig, HostMsg::Release);
    let mut blocks = vec![];
    loop {
        let t = rig.now_us() + 100_000;
        rig.advance_to(t);
        let mut ended = false;
        for f in rig.take_output().split_inclusive(|&b| b == 0) {
            let m = decode_one::<DeviceMsg>(f).unwrap().msg;
            if let Some(b) = m.sample_block() {
                blocks.push(b.unwrap());
            }
            ended |= matches!(m, DeviceMsg::RunEnded(_));
        }
        if ended {
            return blocks;
        }
    }
}

fn ratio() {
    println!(
        "== compression ratio (codec: per-channel level/slope/curve prediction, Rice codes) =="
    );
    let mut s = Sizes::default();
    for b in physics_blocks(0.3, FrictionLaw::coulomb_viscous(0.02, 0.004), 3.0) {
        s.add(&b);
    }
    s.print("tribo-physics record, 0.3 N Coulomb–viscous contact, 3 s (x, v, F)");
    let mut s = Sizes::default();
    for b in physics_blocks(0.0, FrictionLaw::polynomial(vec![0.0, 0.0]), 40.0) {
        s.add(&b);
    }
    s.print("tribo-physics record, unloaded (apparatus damping only), 40 s (x, v, F)");
    let loaded = VirtualRigConfig {
        law: tribo_physics::FrictionLaw::coulomb_viscous(0.02, 0.004),
        ..Default::default()
    };
    let mut s = Sizes::default();
    for b in rig_blocks(loaded, 0.3, 10.0) {
        s.add(&b);
    }
    s.print("virtual rig, 0.3 N Coulomb–viscous, run to rest (x, v, F, ECR, T)");
    let unloaded = VirtualRigConfig {
        load_n: 0.0,
        ..Default::default()
    };
    let mut s = Sizes::default();
    for b in rig_blocks(unloaded, 0.0, 60.0) {
        s.add(&b);
    }
    s.print("virtual rig, unloaded, 60 s (x, v, F, ECR, T)");
}

// ------------------------------------------------------------------------------------------------
// Rig-side cost
// ------------------------------------------------------------------------------------------------

/// What the rig does with each finished block: pack it, frame it, store it (RAM ring), and move the
/// flash copy along. Not inlined, so that callgrind can count it alone (`--toggle-collect`).
#[inline(never)]
fn rig_side(
    blocks: &[SampleBlock],
    store: &mut RunStore,
    flash: &mut MemFlash<Vec<u8>>,
    enc: &mut Encoder,
    out: &mut [u8; MAX_FRAME],
) -> usize {
    let mut bytes = 0;
    for (seq, b) in blocks.iter().enumerate() {
        let p = PackedBlock::pack(b).unwrap();
        let k = p.block;
        let frame = enc.encode(seq as u32, &DeviceMsg::Packed(p), out).unwrap();
        bytes += frame.len();
        store.push_block(k, frame);
        store.service(flash);
    }
    bytes
}

fn cost() {
    println!("== rig-side cost per sample (pack + frame + store + flash copy) ==");
    let unloaded = VirtualRigConfig {
        load_n: 0.0,
        ..Default::default()
    };
    let blocks = rig_blocks(unloaded, 0.0, 20.0);
    let samples: usize = blocks.iter().map(|b| b.samples()).sum();
    let ring: Vec<&'static mut [u8]> = BOARD_RING_BYTES
        .iter()
        .map(|&n| -> &'static mut [u8] { Box::leak(vec![0u8; n].into_boxed_slice()) })
        .collect();
    let index: &'static mut [u32] = Box::leak(vec![0u32; MAX_RUN_BLOCKS].into_boxed_slice());
    let mut store = RunStore::new(ring, index);
    let mut flash = MemFlash::new(
        vec![0xFF; FlashGeometry::H743_BANK2.bytes() as usize],
        FlashGeometry::H743_BANK2,
    );
    let mut enc = Encoder::new();
    let mut out = [0u8; MAX_FRAME];
    let header = encode_vec(
        0,
        &DeviceMsg::RunStarted(RunHeader {
            run_id: 1,
            config: Configure::real_rig(0.0),
            temp_c: 25.0,
            t_us: 0,
            clock: tribo_wire::SampleClock::exact(10_000),
        }),
    )
    .unwrap();
    assert!(store.begin(&flash, 1, &header));
    let t = Instant::now();
    let bytes = rig_side(&blocks, &mut store, &mut flash, &mut enc, &mut out);
    let wall = t.elapsed();
    println!(
        "  {samples} samples ({} blocks, 5 channels) in {:.1} ms: {:.0} ns/sample on this host, {bytes} B \
         of frames; {} flash words programmed",
        blocks.len(),
        wall.as_secs_f64() * 1e3,
        wall.as_secs_f64() * 1e9 / samples as f64,
        flash.programmed_words()
    );
    println!(
        "  instructions: run under callgrind with --toggle-collect='*rig_side*' and divide the total by \
         {samples}"
    );
    assert!(
        !flash.flash_take_error(),
        "the flash model reported a failure"
    );
}

// ------------------------------------------------------------------------------------------------
// Link
// ------------------------------------------------------------------------------------------------

fn link() {
    println!(
        "== link: the virtual rig over a byte stream (Unix socket), host decoding every frame =="
    );
    for (rate, speed) in [(20_000u32, f64::INFINITY), (20_000, 1.0)] {
        let rig = VirtualRig::new(VirtualRigConfig {
            load_n: 0.0,
            ..Default::default()
        })
        .unwrap();
        let seconds = if speed.is_finite() { 5.0 } else { 20.0 };
        let (host, dev) = UnixStream::pair().unwrap();
        let dev_r = dev.try_clone().unwrap();
        let server = std::thread::spawn(move || {
            let mut rig = rig;
            let _ = serve(
                &mut rig,
                dev_r,
                dev,
                &ServeOptions {
                    speed,
                    max_wait: Duration::from_millis(1),
                    ..Default::default()
                },
            );
        });
        let mut host_w = host.try_clone().unwrap();
        let mut host_r = host;
        let mut c = Configure::real_rig(0.0);
        c.sample_rate_hz = rate;
        c.max_duration_s = seconds;
        for (seq, m) in [HostMsg::Configure(c), HostMsg::Arm]
            .into_iter()
            .enumerate()
        {
            host_w
                .write_all(&encode_vec(seq as u32, &m).unwrap())
                .unwrap();
        }
        std::thread::sleep(Duration::from_millis(if speed.is_finite() {
            400
        } else {
            50
        }));
        host_w
            .write_all(&encode_vec(10, &HostMsg::Release).unwrap())
            .unwrap();
        let mut dec = Decoder::<DeviceMsg>::new();
        let mut buf = vec![0u8; 1 << 16];
        let (mut bytes, mut blocks, mut samples, mut bad) = (0usize, 0u32, 0u64, 0u32);
        let mut t_first: Option<Instant> = None;
        let mut ended = false;
        host_r
            .set_read_timeout(Some(Duration::from_secs(30)))
            .unwrap();
        while !ended {
            let n = match host_r.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(n) => n,
            };
            dec.feed(&buf[..n], |r| match r {
                Ok(f) => {
                    if f.msg.is_run_frame() {
                        t_first.get_or_insert_with(Instant::now);
                    }
                    match &f.msg {
                        DeviceMsg::Packed(p) => {
                            blocks += 1;
                            samples += p.unpack().map(|b| b.samples() as u64).unwrap_or(0);
                        }
                        DeviceMsg::RunEnded(_) => ended = true,
                        _ => {}
                    }
                }
                Err(_) => bad += 1,
            });
            if t_first.is_some() {
                bytes += n;
            }
        }
        let wall = t_first.map_or(0.0, |t| t.elapsed().as_secs_f64());
        let device_s = samples as f64 / rate as f64;
        println!(
            "  {rate} S/s × 5 channels, speed {}: {blocks} blocks, {:.2} device-s in {wall:.2} s wall: \
             {:.0} kB per device-second; the link moved {:.0} kB/s ({:.0} kS/s of five channels, ×{:.1} \
             real time); {bad} bad frames",
            if speed.is_finite() {
                format!("×{speed}")
            } else {
                "as fast as possible".into()
            },
            device_s,
            bytes as f64 / device_s / 1e3,
            bytes as f64 / wall / 1e3,
            samples as f64 / wall / 1e3,
            device_s / wall,
        );
        drop(host_w);
        drop(host_r);
        let _ = server.join();
    }
}
