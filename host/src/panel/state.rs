//! What the pages show: the rig's state, the plate's temperature history, the run being recorded
//! (decimated for drawing; the store keeps every block), its result and the campaign grid.

use crate::link::state_name;
use serde_json::{json, Value};
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;
use tribo_store::catalog::{AnyCatalog, Axis, Filter, RunCatalog, Value as CatValue};
use tribo_store::Run;
use tribo_wire::{limits, Channel, Control, Gap, RunHeader, SampleBlock, Status};

/// Samples per drawn bucket (min and max of each channel): two buckets per 64-sample block.
pub const BUCKET: usize = 32;
/// The plate's history kept for the page, seconds.
pub const HISTORY_S: f64 = 600.0;

/// The channels drawn, in the order of a bucket's values.
pub const DRAWN: [Channel; 4] = [
    Channel::Displacement,
    Channel::Velocity,
    Channel::Force,
    Channel::Ecr,
];

/// One block, decimated for drawing.
#[derive(Debug, Clone)]
pub struct DrawnBlock {
    pub block: u32,
    /// Time of its first sample, s after the run's first sample.
    pub t0: f64,
    /// Seconds per bucket.
    pub dt: f64,
    /// Per bucket: min and max of each drawn channel present (NaN when absent).
    pub buckets: Vec<[f32; 8]>,
    /// The envelope at the block's last sample, m.
    pub envelope_m: f64,
    pub t_end: f64,
}

/// The run being recorded, as drawn.
#[derive(Debug, Clone)]
pub struct Trace {
    pub run_id: u32,
    pub header: RunHeader,
    pub dir: PathBuf,
    pub rate: f64,
    /// Blocks in arrival order (blocks fetched again by a pull come late).
    pub blocks: Vec<DrawnBlock>,
    /// Blocks lost on the line (fetched again at the end), as `from..to`.
    pub line_gaps: Vec<(u32, u32)>,
    /// Samples the rig itself lost (acquisition gaps), as times `from..to`.
    pub lost: Vec<(f64, f64)>,
    pub expected: u64,
    pub ended: Option<String>,
}

impl Trace {
    pub fn new(header: &RunHeader, dir: &Path) -> Trace {
        let rate = if header.clock.is_valid() {
            header.clock.rate_hz()
        } else {
            header.config.sample_rate_hz as f64
        };
        Trace {
            run_id: header.run_id,
            header: *header,
            dir: dir.to_path_buf(),
            rate,
            blocks: Vec::new(),
            line_gaps: Vec::new(),
            lost: Vec::new(),
            expected: 0,
            ended: None,
        }
    }

    fn time(&self, sample: u64) -> f64 {
        if self.header.clock.is_valid() {
            self.header.clock.time_s(sample)
        } else {
            sample as f64 / self.rate.max(1.0)
        }
    }

    /// Files a block: min and max of each drawn channel over every [`BUCKET`] samples.
    pub fn block(&mut self, b: &SampleBlock, envelope_m: f64, expected: u64) {
        self.expected = expected;
        let n = b.samples();
        let cal = self.header.config.calibration;
        let cols: Vec<Option<usize>> = DRAWN.iter().map(|c| b.channels.position(*c)).collect();
        let width = b.channels.len();
        let mut buckets = Vec::with_capacity(n.div_ceil(BUCKET));
        for start in (0..n).step_by(BUCKET) {
            let end = (start + BUCKET).min(n);
            let mut v = [f32::NAN; 8];
            for (k, (col, ch)) in cols.iter().zip(DRAWN).enumerate() {
                let Some(col) = col else { continue };
                let c = cal[ch as usize];
                let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                for i in start..end {
                    let x = c.to_si(b.counts[i * width + col]);
                    lo = lo.min(x);
                    hi = hi.max(x);
                }
                v[2 * k] = lo;
                v[2 * k + 1] = hi;
            }
            buckets.push(v);
        }
        let t0 = self.time(b.first_sample as u64);
        self.blocks.push(DrawnBlock {
            block: b.block,
            t0,
            dt: BUCKET as f64 / self.rate.max(1.0),
            buckets,
            envelope_m,
            t_end: self.time(b.first_sample as u64 + n.saturating_sub(1) as u64),
        });
    }

    pub fn line_gap(&mut self, from: u32, to: u32) {
        self.line_gaps.push((from, to));
    }

    pub fn lost(&mut self, g: &Gap) {
        let a = self.time(g.first_sample as u64);
        let b = self.time(g.first_sample as u64 + g.count as u64);
        self.lost.push((a, b));
    }

    /// Blocks `from..` (in arrival order) as JSON for the page: `{"run", "from", "blocks": [{"b",
    /// "t0", "dt", "v": [min, max of each drawn channel per bucket…], "env", "te"}]}`. The values
    /// are written as the shortest text that reads back to the same `f32` (a third of the bytes of
    /// `f64` text), `null` where not finite.
    pub fn blocks_json(&self, from: usize) -> String {
        use std::fmt::Write;
        let mut out = format!(r#"{{"run":{},"from":{from},"blocks":["#, self.run_id);
        for (n, b) in self.blocks[from.min(self.blocks.len())..]
            .iter()
            .enumerate()
        {
            if n > 0 {
                out.push(',');
            }
            let _ = write!(
                out,
                r#"{{"b":{},"t0":{},"dt":{},"v":["#,
                b.block, b.t0, b.dt
            );
            for (k, x) in b.buckets.iter().flatten().enumerate() {
                if k > 0 {
                    out.push(',');
                }
                if x.is_finite() {
                    let _ = write!(out, "{x}");
                } else {
                    out.push_str("null");
                }
            }
            let _ = write!(
                out,
                r#"],"env":{},"te":{}}}"#,
                num(b.envelope_m),
                num(b.t_end)
            );
        }
        out.push_str("]}");
        out
    }

    fn summary(&self) -> Value {
        let missing: Vec<(u32, u32)> = self.line_gaps.clone();
        json!({
            "run": self.run_id,
            "rate": self.rate,
            "a0": self.header.config.initial_amplitude_m,
            "load_n": self.header.config.rig.load_n,
            "dir": self.dir.display().to_string(),
            "blocks": self.blocks.len(),
            "expected": self.expected,
            "line_gaps": missing,
            "lost": self.lost,
            "ended": self.ended,
        })
    }
}

/// A JSON number, or null for a value that is not finite.
fn num(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

/// Everything the pages show, shared between the link thread and the page servers.
pub struct Shared {
    /// Bumped on every change; the event streams send the state when it moved.
    pub version: u64,
    pub connected: bool,
    pub port: Option<String>,
    pub serial: Option<String>,
    pub firmware: Option<String>,
    pub boot: Option<String>,
    /// Why the link is down.
    pub link_error: Option<String>,
    status: Option<Status>,
    fault: Option<String>,
    started: Instant,
    /// (s since the panel started, plate °C, setpoint °C).
    temps: VecDeque<(f64, f32, Option<f32>)>,
    settled_since: Option<Instant>,
    pub busy: Option<String>,
    /// The last answer shown: (ok, text, number).
    message: Option<(bool, String, u64)>,
    messages: u64,
    pub trace: Option<Trace>,
    pub result: Option<Value>,
    pub grid: Value,
    /// The page that controls the rig: its id and when its event stream was last alive.
    pub controller: Option<(String, Instant)>,
    pub store: PathBuf,
    /// Requests refused because they were not addressed to this panel (another `Host` or
    /// `Origin`): how many, and why the last one was.
    pub refused: (u64, Option<String>),
}

impl Shared {
    pub fn new(store: PathBuf) -> Shared {
        let grid = grid(&store);
        Shared {
            version: 1,
            connected: false,
            port: None,
            serial: None,
            firmware: None,
            boot: None,
            link_error: Some("connecting…".into()),
            status: None,
            fault: None,
            started: Instant::now(),
            temps: VecDeque::new(),
            settled_since: None,
            busy: None,
            message: None,
            messages: 0,
            trace: None,
            result: None,
            grid,
            controller: None,
            store,
            refused: (0, None),
        }
    }

    pub fn changed(&mut self) {
        self.version += 1;
    }

    pub fn say(&mut self, ok: bool, text: String) {
        self.messages += 1;
        self.message = Some((ok, text, self.messages));
    }

    pub fn connected(&mut self, port: String, serial: String, fw: String, boot: Option<String>) {
        self.say(
            true,
            format!("connected to the rig on {port} (serial {serial})"),
        );
        self.connected = true;
        self.port = Some(port);
        self.serial = Some(serial);
        self.firmware = Some(fw);
        self.boot = boot;
        self.link_error = None;
    }

    pub fn disconnected(&mut self, why: String) {
        if self.connected {
            self.say(false, format!("the rig is disconnected: {why}"));
        }
        self.connected = false;
        self.link_error = Some(why);
        self.busy = None;
        self.settled_since = None;
    }

    pub fn status_snapshot(&self) -> Option<Status> {
        self.status
    }

    /// The rig's state as a run's frames tell it (no status is polled while a run streams).
    pub fn run_state(&mut self, state: tribo_wire::RigState) {
        if let Some(s) = self.status.as_mut() {
            s.state = state;
            s.magnet_on = false;
        }
    }

    pub fn settle_reset(&mut self) {
        self.settled_since = None;
    }

    pub fn status(&mut self, s: Status, fault: Option<String>) {
        let t = self.started.elapsed().as_secs_f64();
        // One point a second in the history (the newest is always the latest reading): what the
        // pages are sent a few times a second stays small.
        let n = self.temps.len();
        let point = (t, s.temp_c, s.heater_setpoint_c);
        if n >= 2 && t - self.temps[n - 2].0 < 1.0 {
            self.temps[n - 1] = point;
        } else {
            self.temps.push_back(point);
        }
        while self
            .temps
            .front()
            .is_some_and(|(t0, _, _)| t - t0 > HISTORY_S)
        {
            self.temps.pop_front();
        }
        // Settled as `tribo run` calls it: within the tolerance for the settling time.
        match s.heater_setpoint_c {
            Some(sp) if (s.temp_c - sp).abs() <= limits::SETTLE_TOL_C => {
                self.settled_since.get_or_insert_with(Instant::now);
            }
            _ => self.settled_since = None,
        }
        self.status = Some(s);
        self.fault = fault;
    }

    fn settled(&self) -> Option<f64> {
        self.settled_since.map(|t| t.elapsed().as_secs_f64())
    }

    /// While the plate is still settling (a setpoint set, the plate not yet within the tolerance
    /// for the settling time, as `tribo run` waits for it): where it is.
    pub fn settling(&self) -> Option<String> {
        let st = self.status.as_ref()?;
        let sp = st.heater_setpoint_c?;
        let for_s = self.settled().unwrap_or(0.0);
        (for_s < limits::SETTLE_S).then(|| {
            format!(
                "the plate is still settling ({:.1} °C → {sp:.1} °C; within ±{} °C for {for_s:.0} of {} s)",
                st.temp_c,
                limits::SETTLE_TOL_C,
                limits::SETTLE_S
            )
        })
    }

    pub fn finish_run(
        &mut self,
        run: &Run,
        table: String,
        incomplete: Option<String>,
        aborted: bool,
    ) {
        let ob = run.result();
        let host = run.host_fit();
        let id = run.id().to_string();
        self.result = Some(json!({
            "run": id,
            "dir": run.dir().display().to_string(),
            "table": table,
            "onboard": ob.map(|r| json!({
                "mu0": num(r.best.mu0 as f64), "mu0_se": num(r.best.mu0_se as f64),
                "mu1": num(r.best.mu1 as f64), "mu1_se": num(r.best.mu1_se as f64),
                "verdict": r.verdict.name(), "cycles": r.cycles,
            })),
            "host": host.map(|h| json!({
                "mu0": num(h.mu0), "mu0_se": num(h.mu0_se),
                "mu1": num(h.mu1), "mu1_se": num(h.mu1_se),
                "verdict": h.verdict.clone(), "converged": h.converged, "gap": num(h.gap),
            })),
            "complete": run.is_complete(),
            "completeness": run.completeness().summary(),
            "incomplete": incomplete,
            "aborted": aborted,
            "report": Value::Null,
        }));
        self.say(
            run.is_complete(),
            format!("run {id} saved in {}", run.dir().display()),
        );
        self.grid = grid(&self.store);
    }

    /// The state as the pages read it (the trace's blocks go separately).
    pub fn to_json(&self, client: Option<&str>) -> Value {
        let st = self.status.map(|s| {
            json!({
                "state": format!("{:?}", s.state).to_lowercase(),
                "state_text": state_name(s.state),
                "run_id": s.run_id,
                "temp_c": num(s.temp_c as f64),
                "setpoint_c": s.heater_setpoint_c,
                "duty": s.heater_duty,
                "heater_fault": s.heater_fault.map(crate::link::heater_fault_text),
                "magnet_on": s.magnet_on,
                "lease": match (s.heater_setpoint_c.is_some() || s.magnet_on, s.control) {
                    (_, Control::StandAlone) => "the technician at the rig (stand-alone mode)",
                    (false, _) => "not needed: nothing heats or holds",
                    (true, Control::Host) => "held by this panel (heartbeat every second)",
                    (true, Control::None) => "nobody holds it: heater and magnet are going off",
                },
                "last_fault": self.fault,
                "faults": s.faults,
                "reset": crate::link::reset_cause_text(s.reset_cause),
                "uptime": crate::link::uptime(s.uptime_ms),
            })
        });
        let t_now = self.started.elapsed().as_secs_f64();
        let temps: Vec<Value> = self
            .temps
            .iter()
            .map(|(t, c, sp)| json!([((t - t_now) * 10.0).round() / 10.0, num(*c as f64), sp]))
            .collect();
        let control = match (&self.controller, client) {
            (None, _) => "free",
            (Some((id, _)), Some(c)) if id == c => "you",
            _ => "other",
        };
        json!({
            "version": self.version,
            "connected": self.connected,
            "port": self.port,
            "serial": self.serial,
            "firmware": self.firmware,
            "boot": self.boot,
            "link_error": self.link_error,
            "status": st,
            "temps": temps,
            "settle_tol_c": limits::SETTLE_TOL_C,
            "settle_s": limits::SETTLE_S,
            "settled_for_s": self.settled(),
            "busy": self.busy,
            "message": self.message.as_ref().map(|(ok, t, n)| json!({"ok": ok, "text": t, "n": n})),
            "trace": self.trace.as_ref().map(Trace::summary),
            "result": self.result,
            "grid": self.grid,
            "control": control,
            "refused": {"count": self.refused.0, "last": self.refused.1},
        })
    }
}

/// The campaign grid from the store's catalog: host μ0 mean ± sd per load × temperature cell
/// (what `tribo table` prints), or an empty grid when the store has no complete run.
pub fn grid(store: &Path) -> Value {
    let Ok(cat) = RunCatalog::open(store) else {
        return json!(null);
    };
    // Up to date with the folders first (a log damaged or cut since it was catalogued), as every
    // other reader of the catalog.
    let _ = cat.refresh(false);
    let Ok(t) = cat.table(Axis::Load, Axis::Temp, CatValue::Mu0, &Filter::default()) else {
        return json!(null);
    };
    let cells: Vec<Vec<Value>> = t
        .cells
        .iter()
        .map(|row| {
            row.iter()
                .map(|c| match c {
                    None => Value::Null,
                    Some(c) => json!({"mean": c.mean, "sd": c.sd, "n": c.n}),
                })
                .collect()
        })
        .collect();
    let labels = |b: &[tribo_store::catalog::Bin]| b.iter().map(|b| b.label()).collect::<Vec<_>>();
    // The runs the grid cannot hold (damaged, incomplete), each with how to repair it: never
    // dropped from it without a word (as `tribo table` says them).
    let left: Vec<Value> = crate::archive::left_out(store, &Filter::default())
        .unwrap_or_default()
        .into_iter()
        .map(|l| {
            json!({
                "run": l.dir.file_name().map(|n| n.to_string_lossy().into_owned()),
                "why": l.why,
            })
        })
        .collect();
    json!({"loads": labels(&t.rows), "temps": labels(&t.cols), "cells": cells, "left_out": left})
}

/// Writes the run's HTML report (as `tribo report RUN -o RUN/report`) on a thread of its own, then
/// links it from the result.
pub fn write_report(shared: Arc<Mutex<Shared>>, id: String, dir: PathBuf) {
    let _ = std::thread::Builder::new()
        .name("tribo-panel-report".into())
        .spawn(move || {
            // What `tribo report RUN -o RUN/report` does for a run folder (the default laws, SVG).
            let r = (|| -> anyhow::Result<()> {
                let opened = crate::load::open(&dir, crate::Holes::Keep)?;
                let run = anyhow::Context::context(opened.run, "not a run folder")?;
                let mut inputs = tribo_report::store::run_inputs(&run);
                inputs.options.png = false;
                tribo_report::write_record_report(&opened.record, &inputs, &dir.join("report"))?;
                Ok(())
            })();
            let mut s = match shared.lock() {
                Ok(s) => s,
                Err(p) => p.into_inner(),
            };
            if let Some(res) = s.result.as_mut().filter(|r| r["run"] == id.as_str()) {
                res["report"] = match r {
                    Ok(()) => json!(format!(
                        "/report/{}/report.html",
                        dir.file_name()
                            .map_or(String::new(), |n| n.to_string_lossy().into_owned())
                    )),
                    Err(e) => json!({"error": format!("{e:#}")}),
                };
            }
            s.changed();
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use tribo_wire::{ChannelSet, Configure, Counts, SampleClock, BLOCK_LEN};

    fn header(rate: u32) -> RunHeader {
        let mut config = Configure::real_rig(0.3);
        config.sample_rate_hz = rate;
        RunHeader {
            run_id: 7,
            config,
            temp_c: 22.0,
            t_us: 0,
            clock: SampleClock::exact(rate),
        }
    }

    /// A block of every channel whose counts follow a formula of (sample, channel).
    fn block(k: u32, count: impl Fn(u32, usize) -> u16) -> SampleBlock {
        let set = ChannelSet::ALL;
        let mut counts = Counts::default();
        for i in 0..BLOCK_LEN as u32 {
            for c in 0..set.len() {
                counts.push(count(k * BLOCK_LEN as u32 + i, c)).unwrap();
            }
        }
        SampleBlock {
            run_id: 7,
            block: k,
            first_sample: k * BLOCK_LEN as u32,
            t_us: 0,
            channels: set,
            ecr_range: 0,
            log10_ecr_ohm: 0.0,
            temp_c: 22.0,
            counts,
        }
    }

    #[test]
    fn each_bucket_holds_the_true_min_and_max_of_its_samples_in_si_units() {
        let h = header(20_000);
        let mut t = Trace::new(&h, Path::new("run"));
        // A different pseudo-random walk per channel.
        let f =
            |i: u32, c: usize| (((i as u64 * 2_654_435_761 + c as u64 * 97) >> 7) % 65_536) as u16;
        for k in 0..3 {
            t.block(&block(k, f), 1e-4, 1000);
        }
        assert_eq!(t.blocks.len(), 3);
        let cal = h.config.calibration;
        for (k, b) in t.blocks.iter().enumerate() {
            assert_eq!(b.buckets.len(), BLOCK_LEN.div_ceil(BUCKET));
            assert!((b.t0 - (k * BLOCK_LEN) as f64 / 20_000.0).abs() < 1e-12);
            for (j, v) in b.buckets.iter().enumerate() {
                for (d, ch) in DRAWN.iter().enumerate() {
                    let pos = ChannelSet::ALL.position(*ch).unwrap();
                    let vals: Vec<f32> = (0..BUCKET)
                        .map(|s| (k * BLOCK_LEN + j * BUCKET + s) as u32)
                        .map(|i| cal[*ch as usize].to_si(f(i, pos)))
                        .collect();
                    let lo = vals.iter().cloned().fold(f32::INFINITY, f32::min);
                    let hi = vals.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
                    assert_eq!(
                        (v[2 * d], v[2 * d + 1]),
                        (lo, hi),
                        "block {k} bucket {j} {ch:?}"
                    );
                }
            }
        }
        // The page is sent the blocks it lacks, every one of them.
        let j: Value = serde_json::from_str(&t.blocks_json(1)).unwrap();
        assert_eq!(
            j["blocks"][0]["v"][0].as_f64().unwrap() as f32,
            t.blocks[1].buckets[0][0]
        );
        let sent: Vec<u64> = j["blocks"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b["b"].as_u64().unwrap())
            .collect();
        assert_eq!(sent, vec![1, 2]);
    }

    #[test]
    fn a_channel_not_recorded_is_drawn_as_nothing() {
        let h = header(10_000);
        let mut t = Trace::new(&h, Path::new("run"));
        let mut b = block(0, |_, _| 40_000);
        b.channels = ChannelSet::EMPTY
            .with(Channel::Displacement)
            .with(Channel::Velocity);
        b.counts = Counts::from_slice(&vec![40_000; 2 * BLOCK_LEN]).unwrap();
        t.block(&b, f64::NAN, 0);
        let v = t.blocks[0].buckets[0];
        assert!(v[0].is_finite() && v[3].is_finite());
        assert!(v[4..].iter().all(|x| x.is_nan()), "{v:?}");
        let j: Value = serde_json::from_str(&t.blocks_json(0)).unwrap();
        assert!(j["blocks"][0]["v"][4].is_null() && j["blocks"][0]["env"].is_null());
    }

    /// The panel keeps up with 20 kS/s × 5 channels with room to spare: filing a second's blocks
    /// and writing them as the page's JSON takes a small part of that second (printed with
    /// `--nocapture`; the bound is loose for a busy, unoptimised test build).
    #[test]
    fn a_second_at_20_ks_per_s_is_filed_and_sent_in_a_fraction_of_a_second() {
        let h = header(20_000);
        let mut t = Trace::new(&h, Path::new("run"));
        let blocks: Vec<SampleBlock> = (0..(20_000 / BLOCK_LEN as u32))
            .map(|k| block(k, |i, c| ((i * 7 + c as u32 * 13) % 65_536) as u16))
            .collect();
        let t0 = Instant::now();
        for b in &blocks {
            t.block(b, 1e-4, 0);
        }
        let json = t.blocks_json(0);
        let took = t0.elapsed();
        crate::errln!(
            "one second at 20 kS/s × 5 channels: {} blocks filed and sent ({} kB of JSON) in {took:?}",
            blocks.len(),
            json.len() / 1000
        );
        assert!(took.as_secs_f64() < 0.5, "{took:?}");
    }
}
