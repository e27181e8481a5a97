//! Round trips through a run folder and the catalog.

use crate::catalog::{AnyCatalog, Axis, Bin, Value, CATALOG_FILE};
use crate::*;
use tribo_wire::frame::{decode_one, encode_vec};
use tribo_wire::*;

/// Frames of a synthetic run: a decaying sine of amplitude `a0`, `nblocks` full blocks.
fn run_frames(cfg: &Configure, nblocks: u32, mu0: f32) -> Vec<Vec<u8>> {
    let w = cfg.omega() as f64;
    let rate = cfg.sample_rate_hz as f64;
    let mut out = vec![];
    let mut seq = 0;
    let mut push = |m: DeviceMsg| {
        seq += 1;
        out.push(encode_vec(seq, &m).unwrap());
    };
    push(DeviceMsg::RunStarted(RunHeader {
        run_id: 7,
        config: *cfg,
        temp_c: 41.5,
        t_us: 1000,
        clock: SampleClock {
            timer_hz: 200_000_000,
            ticks_per_sample: 200_000_000 / cfg.sample_rate_hz,
        },
    }));
    for b in 0..nblocks {
        let mut counts = Counts::default();
        for i in 0..BLOCK_LEN {
            let t = (b as usize * BLOCK_LEN + i) as f64 / rate;
            let x = cfg.initial_amplitude_m as f64 * (-t).exp() * (w * t).cos();
            let v = -cfg.initial_amplitude_m as f64 * w * (-t).exp() * (w * t).sin();
            let vals = [x, v, 0.01 * v.signum(), 1.0, 41.5];
            for c in cfg.channels.iter() {
                counts
                    .push(cfg.calibration[c.index()].to_count(vals[c.index()] as f32))
                    .unwrap();
            }
        }
        push(DeviceMsg::Samples(SampleBlock {
            run_id: 7,
            block: b,
            first_sample: b * BLOCK_LEN as u32,
            t_us: 1000 + (b as u64 * BLOCK_LEN as u64 * 100),
            channels: cfg.channels,
            ecr_range: 2,
            log10_ecr_ohm: 6.5,
            temp_c: 41.5,
            counts,
        }));
    }
    let est = Estimate {
        mu0,
        mu1: 0.01,
        mu0_se: 0.0001,
        mu1_se: f32::NAN,
    };
    push(DeviceMsg::Result(OnboardResult {
        run_id: 7,
        verdict: Verdict::Ok,
        cycles: 12,
        frequency_hz: 26.9,
        initial_amplitude_m: cfg.initial_amplitude_m,
        duration_s: 1.0,
        best: est,
        averaging: est,
        decrement: est,
        shape: EnvelopeShape::Straight,
        curvature: 0.0,
    }));
    push(DeviceMsg::RunEnded(RunEnd {
        run_id: 7,
        blocks: nblocks,
        samples: nblocks * BLOCK_LEN as u32,
        overruns: 0,
        reason: EndReason::Stopped,
    }));
    out
}

fn record(
    store: &std::path::Path,
    cfg: &Configure,
    frames: &[Vec<u8>],
    meta_fn: impl FnOnce(&mut RunMeta),
) -> Run {
    let mut meta = RunMeta::new(*cfg);
    meta_fn(&mut meta);
    let mut w = RunWriter::create(store, meta).unwrap();
    for f in frames {
        w.append_frame(f).unwrap();
    }
    w.finish(false).unwrap()
}

#[test]
fn samples_round_trip_through_the_store() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let frames = run_frames(&cfg, 20, 0.02);
    let run = record(d.path(), &cfg, &frames, |m| {
        m.label = Some("steel/PAO".into())
    });
    assert_eq!(run.meta.status, RunStatus::Complete);
    assert!(run.is_complete());
    assert!(run.meta.id.ends_with("steel_PAO"), "{}", run.meta.id);
    assert_eq!(run.meta.device_run_id, Some(7));
    assert_eq!(run.meta.temp_c, Some(41.5));
    let s = run.samples_si().unwrap();
    assert_eq!(s.len(), 20 * BLOCK_LEN);
    let w = cfg.omega() as f64;
    let qx = cfg.calibration[0].gain as f64;
    let qv = cfg.calibration[1].gain as f64;
    for i in 0..s.len() {
        let t = i as f64 / 10_000.0;
        assert!((s.t[i] - t).abs() < 1e-12);
        let x = 667e-6 * (-t).exp() * (w * t).cos();
        let v = -667e-6 * w * (-t).exp() * (w * t).sin();
        assert!(
            (s.x[i] - x).abs() <= 0.51 * qx + 1e-12,
            "x at {i}: {} vs {x}",
            s.x[i]
        );
        assert!((s.v[i] - v).abs() <= 0.51 * qv + 1e-9, "v at {i}");
    }
    let ecr = s.ecr_ohm.as_ref().unwrap();
    assert!((ecr[0] / 10f64.powf(6.5) - 1.0).abs() < 1e-6);
    assert!(s
        .temp_c
        .as_ref()
        .unwrap()
        .iter()
        .all(|t| (t - 41.5).abs() < 0.01));
    assert_eq!(run.result().unwrap().best.mu0, 0.02);
    // NaN survives the TOML result file.
    assert!(run.result().unwrap().best.mu1_se.is_nan());
}

#[test]
fn gaps_and_ecr_ranges_are_stored_and_place_every_sample() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    // 9 999 S/s asked; the timer made 200 MHz / 20 002.
    let clock = SampleClock {
        timer_hz: 200_000_000,
        ticks_per_sample: 20_002,
    };
    let mut frames = run_frames(&cfg, 6, 0.02);
    let header = frames.remove(0);
    let mut h = match decode_one::<DeviceMsg>(&header).unwrap().msg {
        DeviceMsg::RunStarted(h) => h,
        _ => unreachable!(),
    };
    h.clock = clock;
    let mut out = vec![encode_vec(1, &DeviceMsg::RunStarted(h)).unwrap()];
    let ev = |seq, m| encode_vec(seq, &m).unwrap();
    out.push(ev(
        2,
        DeviceMsg::EcrRange(EcrRangeChange {
            run_id: 7,
            first_sample: 0,
            range: 3,
            settling: 0,
        }),
    ));
    // Blocks 0, 1 hold samples 0..128; then 300 lost; blocks 2.. start at 428.
    let mut blocks: Vec<SampleBlock> = frames
        .iter()
        .filter_map(|f| match decode_one::<DeviceMsg>(f).unwrap().msg {
            DeviceMsg::Samples(b) => Some(b),
            _ => None,
        })
        .collect();
    for b in blocks.iter_mut().skip(2) {
        b.first_sample += 300;
    }
    let tail: Vec<Vec<u8>> = frames
        .iter()
        .filter(|f| {
            !matches!(
                decode_one::<DeviceMsg>(f).unwrap().msg,
                DeviceMsg::Samples(_)
            )
        })
        .cloned()
        .collect();
    let gap = Gap {
        run_id: 7,
        first_sample: 128,
        count: 300,
    };
    for (k, b) in blocks.into_iter().enumerate() {
        if k == 2 {
            out.push(ev(50, DeviceMsg::Gap(gap)));
        }
        if k == 4 {
            out.push(ev(
                60,
                DeviceMsg::EcrRange(EcrRangeChange {
                    run_id: 7,
                    first_sample: 600,
                    range: 2,
                    settling: 21,
                }),
            ));
        }
        out.push(ev(10 + k as u32, DeviceMsg::Samples(b)));
    }
    out.extend(tail);
    // A frame received twice (live, then by a Pull) is stored once.
    out.push(ev(50, DeviceMsg::Gap(gap)));
    let run = record(d.path(), &cfg, &out, |_| {});
    assert_eq!(run.gaps().copied().collect::<Vec<_>>(), [gap]);
    assert_eq!(run.lost_samples(), 300);
    assert_eq!(run.clock(), clock);
    assert_eq!(run.clean_stretches(), [0..128, 428..428 + 4 * 64]);
    let s = run.samples_si().unwrap();
    assert_eq!(s.len(), 6 * BLOCK_LEN);
    // Times from the clock: sample i at i × 20 002 / 200 MHz, across the gap too.
    for (k, &i) in s.index.iter().enumerate() {
        assert_eq!(s.t[k], clock.time_s(i));
    }
    assert_eq!(s.index[128], 428);
    // Each sample's range, and the settling after the change at 600.
    let r = s.ecr_range.as_ref().unwrap();
    let st = s.ecr_settling.as_ref().unwrap();
    let at = |i: u64| s.index.iter().position(|&x| x == i).unwrap();
    assert_eq!((r[at(599)], st[at(599)]), (3, false));
    assert_eq!((r[at(600)], st[at(600)]), (2, true));
    assert_eq!((r[at(620)], st[at(620)]), (2, true));
    assert_eq!((r[at(621)], st[at(621)]), (2, false));
    // The catalog marks it.
    let cat = RunCatalog::open(d.path()).unwrap();
    cat.upsert(&run).unwrap();
    let rows = cat.list(&Filter::default()).unwrap();
    assert_eq!(rows[0].lost_samples, 300);
}

#[test]
fn a_header_without_a_valid_clock_reads_at_the_configured_rate() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let mut frames = run_frames(&cfg, 2, 0.02);
    let mut h = match decode_one::<DeviceMsg>(&frames[0]).unwrap().msg {
        DeviceMsg::RunStarted(h) => h,
        _ => unreachable!(),
    };
    h.clock = SampleClock {
        timer_hz: 0,
        ticks_per_sample: 0,
    };
    frames[0] = encode_vec(1, &DeviceMsg::RunStarted(h)).unwrap();
    let run = record(d.path(), &cfg, &frames, |_| {});
    assert_eq!(run.clock(), SampleClock::exact(10_000));
    let s = run.samples_si().unwrap();
    assert_eq!(s.t[100], 0.01);
    assert!(s.ecr_range.is_none());
}

#[test]
fn csv_export_reads_back_as_a_physics_record() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.45);
    let run = record(d.path(), &cfg, &run_frames(&cfg, 4, 0.02), |_| {});
    let path = d.path().join("x.csv");
    run.export_csv(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.starts_with("# mass_kg="), "{}", &text[..60]);
    let back = tribo_physics::Record::from_csv_str(&text).unwrap();
    let orig = run.record().unwrap();
    assert_eq!(back.rig, orig.rig);
    assert_eq!(back.len(), orig.len());
    for i in 0..back.len() {
        assert!((back.x[i] - orig.x[i]).abs() <= 1e-15 + 1e-12 * orig.x[i].abs());
        assert!((back.v[i] - orig.v[i]).abs() <= 1e-15 + 1e-12 * orig.v[i].abs());
    }
    assert!(back.ft.is_some() && back.temp.is_some() && back.ecr.is_some());
}

#[test]
fn killed_recorder_leaves_a_readable_resumable_run() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let frames = run_frames(&cfg, 10, 0.02);
    let mut w = RunWriter::create(d.path(), RunMeta::new(cfg)).unwrap();
    for f in &frames[..6] {
        w.append_frame(f).unwrap();
    }
    let dir = w.dir().to_owned();
    drop(w); // killed: no finish
             // And half of a 7th record made it to disk.
    let log = dir.join(run::LOG_FILE);
    let mut bytes = std::fs::read(&log).unwrap();
    let extra = &frames[6];
    bytes.extend_from_slice(&(extra.len() as u32).to_le_bytes());
    bytes.extend_from_slice(&[1, 2, 3, 4]);
    bytes.extend_from_slice(&extra[..extra.len() / 2]);
    std::fs::write(&log, &bytes).unwrap();

    let run = Run::open(&dir).unwrap();
    assert_eq!(run.meta.status, RunStatus::Recording);
    assert!(!run.is_complete());
    assert_eq!(run.block_count(), 5);
    assert_eq!(run.resume_from(), 5);
    assert!(run.recovery.is_some());
    assert_eq!(run.samples_si().unwrap().len(), 5 * BLOCK_LEN);

    // Resume: the torn tail is cut and the rest appended; blocks already held are deduplicated.
    let (mut w, rec) = RunWriter::resume(&dir, false).unwrap();
    assert_eq!(rec.unwrap().records, 6);
    for f in &frames[3..] {
        w.append_frame(f).unwrap();
    }
    let run = w.finish(false).unwrap();
    assert!(run.recovery.is_none());
    assert!(run.is_complete(), "missing {:?}", run.missing_blocks());
    assert_eq!(run.meta.status, RunStatus::Complete);
    assert_eq!(run.samples_si().unwrap().len(), 10 * BLOCK_LEN);
}

#[test]
fn gaps_are_reported_not_papered_over() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let frames = run_frames(&cfg, 8, 0.02);
    // Drop blocks 2 and 5 (frames 3 and 6).
    let kept: Vec<Vec<u8>> = frames
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != 3 && *i != 6)
        .map(|(_, f)| f.clone())
        .collect();
    let run = record(d.path(), &cfg, &kept, |_| {});
    assert_eq!(run.missing_blocks(), vec![2, 5]);
    assert_eq!(run.meta.status, RunStatus::Incomplete);
    assert_eq!(run.resume_from(), 2);
    let s = run.samples_si().unwrap();
    assert_eq!(s.len(), 6 * BLOCK_LEN);
    // Time jumps over the gap instead of shifting samples.
    assert!((s.t[2 * BLOCK_LEN] - (3 * BLOCK_LEN) as f64 / 10_000.0).abs() < 1e-12);
}

#[test]
fn open_reports_what_is_wrong() {
    let d = tempfile::tempdir().unwrap();
    let e = Run::open(d.path().join("nope")).unwrap_err();
    assert!(
        e.msg.contains("not a run folder") && e.msg.contains("tribo runs"),
        "{e}"
    );
    std::fs::write(d.path().join("meta.toml"), "format = \"x\"").unwrap();
    let e = Run::open(d.path()).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Corrupt);
    assert!(e.msg.contains("meta.toml is damaged"), "{e}");
    // The parser's own account (line, column, what it expected) is the source, not lost.
    let toml_err = std::error::Error::source(&e).and_then(|s| s.downcast_ref::<toml::de::Error>());
    assert!(toml_err.is_some(), "{e:?}");
    // A store that cannot be made (a file stands where its folder should): the path, and the
    // io::Error underneath.
    let file = d.path().join("a-file");
    std::fs::write(&file, "").unwrap();
    let Err(e) = RunCatalog::open(&file.join("store")) else {
        panic!("a store made under a file");
    };
    assert_eq!(e.kind, ErrorKind::Io);
    assert!(e.msg.contains("a-file"), "{e}");
    let io = std::error::Error::source(&e).and_then(|s| s.downcast_ref::<std::io::Error>());
    assert!(io.is_some(), "{e:?}");
}

#[test]
fn catalog_lists_filters_and_tabulates_mean_and_sd() {
    let d = tempfile::tempdir().unwrap();
    let mut expected = std::collections::BTreeMap::new();
    for (load, temp) in [(0.2f32, 25.0), (0.2, 60.0), (0.4, 25.0)] {
        for rep in 1..=3u32 {
            let cfg = Configure::real_rig(load);
            let mu0 = 0.01 * load + 0.0001 * temp as f32 + 0.001 * rep as f32;
            let mut run = record(d.path(), &cfg, &run_frames(&cfg, 2, mu0), |m| {
                m.campaign = Some("c1".into());
                m.repeat = Some(rep);
                m.temp_setpoint_c = Some(temp);
                m.label = Some(format!("r{rep}"));
                if temp == 60.0 {
                    // Taken last year, one a day: what --since/--until select by.
                    m.created = format!("2025-06-0{rep}T23:59:59Z");
                }
            });
            let host = HostFit {
                law: tribo_physics::LawSpec::CoulombViscous,
                mu0: mu0 as f64 * 1.01,
                mu1: 0.01,
                gap: 0.001,
                converged: true,
                mu0_se: 1e-4,
                mu1_se: 1e-5,
                verdict: Some("adequate".into()),
            };
            let mut res = run.results.clone();
            res.host = Some(host);
            run.save_results(res).unwrap();
            expected
                .entry((
                    Bin::load(load as f64).unwrap(),
                    Bin::temp(Some(temp)).unwrap(),
                ))
                .or_insert_with(Vec::new)
                .push(mu0 as f64);
        }
    }
    let cat = RunCatalog::open(d.path()).unwrap();
    let r = cat.reindex().unwrap();
    assert_eq!(
        (r.indexed, r.unreadable.len(), r.incomplete.len()),
        (9, 0, 0)
    );
    let all = cat.list(&Filter::default()).unwrap();
    assert_eq!(all.len(), 9);
    let days = |since: Option<&str>, until: Option<&str>| {
        cat.list(&Filter {
            since: since.map(Into::into),
            until: until.map(Into::into),
            ..Default::default()
        })
    };
    let this_year = days(Some("2026-01-01"), None).unwrap();
    assert_eq!(this_year.len(), 6);
    assert!(this_year.iter().all(|r| r.temp_c == Some(25.0)));
    let last_year = days(None, Some("2025-12-31")).unwrap();
    assert_eq!(last_year.len(), 3);
    assert!(last_year.iter().all(|r| r.temp_c == Some(60.0)));
    // Both ends are whole days: a run at 23:59:59 of the day is in.
    // The same store opened by another path (here a link to it; a relative `--store runs` and
    // its absolute path alike): its runs are in the folder it was opened as. (The rows kept the
    // path they were catalogued under, and `tribo runs` called every run "damaged: not in the
    // catalog" when the store was named another way.)
    #[cfg(unix)]
    {
        let other = tempfile::tempdir().unwrap();
        let link = other.path().join("store");
        std::os::unix::fs::symlink(d.path(), &link).unwrap();
        let rows = RunCatalog::open(&link)
            .unwrap()
            .list(&Filter::default())
            .unwrap();
        assert_eq!(rows.len(), 9);
        assert!(
            rows.iter()
                .all(|r| r.path.starts_with(&link) && r.path.is_dir()),
            "{:?}",
            rows[0].path
        );
    }
    let one = days(Some("2025-06-02"), Some("2025-06-02")).unwrap();
    assert_eq!(one.len(), 1);
    assert_eq!(one[0].label.as_deref(), Some("r2"));
    for (since, until) in [
        (Some("2026-13-01"), None),
        (None, Some("26-01-01")),
        (Some("2026-02-01"), Some("2026-01-31")),
    ] {
        let e = days(since, until).unwrap_err().to_string();
        assert!(e.contains("--since") || e.contains("--until"), "{e}");
    }
    let hot = cat
        .list(&Filter {
            temp_min: Some(50.0),
            ..Default::default()
        })
        .unwrap();
    assert_eq!(hot.len(), 3);
    assert!(hot.iter().all(|r| r.temp_c == Some(60.0)));
    let heavy = cat
        .list(&Filter {
            load_min: Some(0.3),
            label: Some("r2".into()),
            ..Default::default()
        })
        .unwrap();
    assert_eq!(heavy.len(), 1);

    let t = cat
        .table(
            Axis::Temp,
            Axis::Load,
            Value::OnboardMu0,
            &Filter::default(),
        )
        .unwrap();
    assert_eq!(t.rows, vec![Bin::SetpointC(25), Bin::SetpointC(60)]);
    assert_eq!(t.cols, vec![Bin::LoadMn(200), Bin::LoadMn(400)]);
    assert!(t.cells[1][1].is_none(), "no run at 60 °C, 0.4 N");
    for (r, temp) in t.rows.iter().enumerate() {
        for (c, load) in t.cols.iter().enumerate() {
            let Some(cell) = t.cells[r][c] else { continue };
            let v = &expected[&(*load, *temp)];
            let mean = v.iter().sum::<f64>() / 3.0;
            let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 2.0).sqrt();
            assert_eq!(cell.n, 3);
            assert!((cell.mean - mean).abs() < 1e-6 * mean.abs().max(1e-3));
            // The repeats differ by 0.001 each: sd = 0.001.
            assert!(
                (cell.sd.unwrap() - sd).abs() < 1e-7 && (sd - 0.001).abs() < 1e-6,
                "{cell:?}"
            );
        }
    }
    let host = cat
        .table(Axis::Temp, Axis::Load, Value::Mu0, &Filter::default())
        .unwrap();
    assert!((host.cells[0][0].unwrap().mean / t.cells[0][0].unwrap().mean - 1.01).abs() < 1e-6);
    let text = t.render();
    assert!(
        text.contains("± 0.00100 (3)") && text.contains('—'),
        "{text}"
    );
    assert!(cat
        .table(Axis::Load, Axis::Load, Value::Mu0, &Filter::default())
        .is_err());
}

#[test]
fn blocks_without_an_ecr_reading_stay_nan_in_samples_and_take_the_nearest_reading_in_the_record() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let mut frames = run_frames(&cfg, 6, 0.02);
    // Blocks 0 and 1 (frames 1, 2): the autoranger had no reading; block 3 (frame 4) neither.
    for (i, f) in frames.iter_mut().enumerate().skip(1).take(6) {
        let tribo_wire::Frame { seq, msg } = tribo_wire::frame::decode_one::<DeviceMsg>(f).unwrap();
        let DeviceMsg::Samples(mut b) = msg else {
            panic!()
        };
        b.log10_ecr_ohm = match i {
            1 | 2 | 4 => f32::NAN,
            _ => 5.0 + i as f32,
        };
        *f = encode_vec(seq, &DeviceMsg::Samples(b)).unwrap();
    }
    let run = record(d.path(), &cfg, &frames, |_| {});
    let s = run.samples_si().unwrap();
    let e = s.ecr_ohm.unwrap();
    assert!(e[0].is_nan() && e[BLOCK_LEN].is_nan() && e[3 * BLOCK_LEN].is_nan());
    assert!((e[2 * BLOCK_LEN] / 1e8 - 1.0).abs() < 1e-5);
    let r = run.record().unwrap();
    r.validate().unwrap();
    let e = r.ecr.unwrap();
    // Leading gap: the first reading (block 2, 10^8); inner gap: the previous one.
    assert!((e[0] / 1e8 - 1.0).abs() < 1e-5 && (e[BLOCK_LEN + 5] / 1e8 - 1.0).abs() < 1e-5);
    assert!((e[3 * BLOCK_LEN] / 1e8 - 1.0).abs() < 1e-5);
    assert!((e[4 * BLOCK_LEN] / 1e10 - 1.0).abs() < 1e-5);
}

/// The frames of `run_frames` with every sample block in its v2 packed form, and, as v2 firmware
/// sends it right after the header, the range the run starts on (a change at sample 0).
fn packed(frames: &[Vec<u8>]) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    for f in frames {
        let fr = tribo_wire::frame::decode_one::<DeviceMsg>(f).unwrap();
        match fr.msg {
            DeviceMsg::Samples(b) => out.push(
                encode_vec(fr.seq, &DeviceMsg::Packed(PackedBlock::pack(&b).unwrap())).unwrap(),
            ),
            DeviceMsg::RunStarted(h) => {
                out.push(f.clone());
                let first = frames.iter().find_map(|g| {
                    match tribo_wire::frame::decode_one::<DeviceMsg>(g).ok()?.msg {
                        DeviceMsg::Samples(b) if b.block == 0 => Some(b.ecr_range),
                        _ => None,
                    }
                });
                out.push(
                    encode_vec(
                        fr.seq.wrapping_add(1_000_000),
                        &DeviceMsg::EcrRange(EcrRangeChange {
                            run_id: h.run_id,
                            first_sample: 0,
                            range: first.unwrap_or(0),
                            settling: 0,
                        }),
                    )
                    .unwrap(),
                );
            }
            _ => out.push(f.clone()),
        }
    }
    out
}

#[test]
fn packed_blocks_read_back_as_the_same_samples() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let v1 = run_frames(&cfg, 20, 0.02);
    let v2 = packed(&v1);
    assert!(
        v2.iter().map(Vec::len).sum::<usize>() * 2 < v1.iter().map(Vec::len).sum::<usize>(),
        "packed frames are smaller"
    );
    let a = record(d.path(), &cfg, &v1, |_| {});
    let b = record(d.path(), &cfg, &v2, |_| {});
    assert!(b.is_complete());
    assert_eq!(b.meta.status, RunStatus::Complete);
    // The same samples (the packed run also says the range it starts on, as v2 firmware does).
    let (sa, sb) = (a.samples_si().unwrap(), b.samples_si().unwrap());
    assert_eq!((&sa.t, &sa.x, &sa.v), (&sb.t, &sb.x, &sb.v));
    assert_eq!(
        (&sa.force, &sa.temp_c, &sa.ecr_ohm),
        (&sb.force, &sb.temp_c, &sb.ecr_ohm)
    );
    // Only the packed run knows each sample's range (from its events): the blocks' own, 2.
    assert!(sb
        .ecr_range
        .as_ref()
        .is_some_and(|r| r.iter().all(|&x| x == 2)));
    assert_eq!(
        a.blocks().cloned().collect::<Vec<_>>(),
        b.blocks().cloned().collect::<Vec<_>>()
    );
    assert_eq!(b.undecodable_records(), 0);
}

#[test]
fn a_packed_block_that_does_not_unpack_counts_as_missing() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let mut frames = packed(&run_frames(&cfg, 10, 0.02));
    // Block 4 re-framed (valid CRC) with a codec format this build does not know (frame 6: after
    // the header and the range the run starts on).
    let fr = tribo_wire::frame::decode_one::<DeviceMsg>(&frames[6]).unwrap();
    let DeviceMsg::Packed(mut p) = fr.msg else {
        panic!("frame 6 is block 4")
    };
    p.data[0] = 9;
    frames[6] = encode_vec(fr.seq, &DeviceMsg::Packed(p)).unwrap();
    let run = record(d.path(), &cfg, &frames, |_| {});
    assert_eq!(run.missing_blocks(), vec![4]);
    assert_eq!(run.undecodable_records(), 1);
    assert!(!run.is_complete());
}

#[test]
fn a_catalog_from_before_the_gap_column_is_migrated() {
    let d = tempfile::tempdir().unwrap();
    let old_schema = "CREATE TABLE runs (id TEXT PRIMARY KEY, path TEXT NOT NULL, created TEXT NOT NULL, \
        status TEXT NOT NULL, label TEXT, sample TEXT, lubricant TEXT, campaign TEXT, repeat INTEGER, \
        load_n REAL NOT NULL, temp_c REAL, firmware TEXT, serial TEXT, samples INTEGER NOT NULL, \
        missing_blocks INTEGER NOT NULL, verdict TEXT, cycles INTEGER, onboard_mu0 REAL, onboard_mu1 REAL, \
        host_mu0 REAL, host_mu1 REAL, host_gap REAL);";
    rusqlite::Connection::open(d.path().join(catalog::CATALOG_FILE))
        .unwrap()
        .execute_batch(old_schema)
        .unwrap();
    let cfg = Configure::real_rig(0.3);
    let run = record(d.path(), &cfg, &run_frames(&cfg, 2, 0.02), |_| {});
    let cat = RunCatalog::open(d.path()).unwrap();
    cat.upsert(&run).unwrap();
    assert_eq!(cat.list(&Filter::default()).unwrap()[0].lost_samples, 0);
    // Opening it again leaves it as it is.
    RunCatalog::open(d.path()).unwrap();
}

#[test]
fn a_v1_log_s_header_without_a_clock_still_reads() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let mut frames = run_frames(&cfg, 3, 0.02);
    let h = match decode_one::<DeviceMsg>(&frames[0]).unwrap().msg {
        DeviceMsg::RunStarted(h) => h,
        _ => unreachable!(),
    };
    // The v1 header: the same fields, no clock (as firmware v1 wrote it).
    let v1 = tribo_wire::v1::DeviceMsg::RunStarted(tribo_wire::v1::RunHeader {
        run_id: h.run_id,
        config: h.config,
        temp_c: h.temp_c,
        t_us: h.t_us,
    });
    frames[0] = encode_vec(1, &v1).unwrap();
    assert!(
        decode_one::<DeviceMsg>(&frames[0]).is_err(),
        "not a v2 frame"
    );
    let run = record(d.path(), &cfg, &frames, |_| {});
    assert_eq!(run.undecodable_records(), 0);
    let hh = run.header().unwrap();
    assert_eq!((hh.run_id, hh.t_us), (h.run_id, h.t_us));
    assert_eq!(run.clock(), SampleClock::exact(10_000));
    assert_eq!(run.samples_si().unwrap().t[10], 0.001);
}

/// The frames of a packed (v2) run of 20 blocks: the ECR range goes from 2 to 3 at block 10 (its
/// change frame sent before block 9, as the rig does), and 100 samples are lost before block 15
/// (a gap frame after block 14); the end says so. Frames in the rig's order.
fn v2_run() -> Vec<Vec<u8>> {
    let cfg = Configure::real_rig(0.3);
    let base = packed(&run_frames(&cfg, 20, 0.02));
    let mut out = vec![];
    let mut seq = 100;
    let mut push = |out: &mut Vec<Vec<u8>>, m: DeviceMsg| {
        seq += 1;
        out.push(encode_vec(seq, &m).unwrap());
    };
    for f in &base {
        match decode_one::<DeviceMsg>(f).unwrap().msg {
            DeviceMsg::Packed(p) => {
                let mut b = p.unpack().unwrap();
                if b.block == 9 {
                    push(
                        &mut out,
                        DeviceMsg::EcrRange(EcrRangeChange {
                            run_id: 7,
                            first_sample: 10 * BLOCK_LEN as u32,
                            range: 3,
                            settling: 5,
                        }),
                    );
                }
                b.ecr_range = if b.block >= 10 { 3 } else { 2 };
                if b.block >= 15 {
                    b.first_sample += 100;
                }
                push(&mut out, DeviceMsg::Packed(PackedBlock::pack(&b).unwrap()));
                if b.block == 14 {
                    push(
                        &mut out,
                        DeviceMsg::Gap(Gap {
                            run_id: 7,
                            first_sample: 15 * BLOCK_LEN as u32,
                            count: 100,
                        }),
                    );
                }
            }
            DeviceMsg::RunEnded(mut e) => {
                e.overruns = 100;
                push(&mut out, DeviceMsg::RunEnded(e));
            }
            m => push(&mut out, m),
        }
    }
    out
}

fn kind(f: &[u8]) -> DeviceMsg {
    decode_one::<DeviceMsg>(f).unwrap().msg
}

#[test]
fn completeness_says_exactly_what_is_missing() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let all = v2_run();
    let whole = record(d.path(), &cfg, &all, |_| {});
    let c = whole.completeness();
    assert!(c.is_complete(), "{}", c.summary());
    assert_eq!(
        c.summary(),
        "complete: 20 of 20 blocks (the rig's acquisition lost 100 samples (its gap frames say which))"
    );
    assert_eq!(whole.meta.status, RunStatus::Complete);
    // The rig's frames, in its order, each once.
    assert_eq!(
        whole.frames(),
        all.iter().map(|f| &f[..]).collect::<Vec<_>>()
    );
    let without = |drop: &dyn Fn(&DeviceMsg) -> bool| -> Run {
        let fr: Vec<Vec<u8>> = all.iter().filter(|f| !drop(&kind(f))).cloned().collect();
        record(d.path(), &cfg, &fr, |_| {})
    };
    let r = without(&|m| matches!(m, DeviceMsg::Packed(p) if [3, 7, 8, 9].contains(&p.block)));
    assert_eq!(
        r.completeness().summary(),
        "incomplete: 16 of 20 blocks (missing 3, 7–9; the rig's acquisition lost 100 samples (its gap \
         frames say which))"
    );
    assert_eq!(r.meta.status, RunStatus::Incomplete);
    let r = without(&|m| matches!(m, DeviceMsg::RunEnded(_)));
    assert!(r
        .completeness()
        .summary()
        .starts_with("incomplete: 20 of at least 20 blocks (the run's end was not received"));
    let r = without(&|m| matches!(m, DeviceMsg::Result(_)));
    assert!(r
        .completeness()
        .summary()
        .starts_with("incomplete: 20 of 20 blocks (the on-board result was not received"));
    let r = without(&|m| matches!(m, DeviceMsg::RunStarted(_)));
    assert!(r.completeness().summary().contains("no run header"));
    // The events: a gap frame lost shows at the block after the jump it explains, a range change
    // at the first block converted on the new range; the end's count of lost samples too.
    let r = without(&|m| matches!(m, DeviceMsg::Gap(_)));
    let c = r.completeness();
    assert_eq!(
        (c.event_holes.clone(), c.gaps_unaccounted),
        (vec![15], Some((0, 100)))
    );
    assert!(
        c.summary().contains("missing before block 15"),
        "{}",
        c.summary()
    );
    let r = without(&|m| matches!(m, DeviceMsg::EcrRange(_)));
    assert_eq!(r.completeness().event_holes, vec![0, 10]);
    assert!(!r.is_complete());
    // The range the run starts on alone: every block agrees with the first one's range, yet the
    // run is not whole (the soak caught a lossy line losing just that frame).
    let r = without(&|m| matches!(m, DeviceMsg::EcrRange(e) if e.first_sample == 0));
    assert_eq!(r.completeness().event_holes, vec![0]);
    assert!(!r.is_complete());
}

#[test]
fn a_frame_is_filed_once_and_another_run_s_frame_is_told_apart() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let all = v2_run();
    let mut w = RunWriter::create(d.path(), RunMeta::new(cfg)).unwrap();
    for f in &all[..10] {
        assert_eq!(w.file_frame(f).unwrap(), Filed::New);
    }
    assert_eq!(w.file_frame(&all[3]).unwrap(), Filed::Same);
    // The same block of another run (other counts): not logged, and said which.
    let DeviceMsg::Packed(p) = kind(&all[3]) else {
        panic!()
    };
    let mut b = p.unpack().unwrap();
    let mut c: Vec<u16> = b.counts.to_vec();
    c[0] ^= 1;
    b.counts = Counts::from_slice(&c).unwrap();
    let other = encode_vec(3, &DeviceMsg::Packed(PackedBlock::pack(&b).unwrap())).unwrap();
    assert_eq!(
        w.file_frame(&other).unwrap(),
        Filed::Differs(format!("its block {}", b.block))
    );
    let hello = encode_vec(1, &DeviceMsg::Ack { seq: 4 }).unwrap();
    assert_eq!(w.file_frame(&hello).unwrap(), Filed::Other);
    assert!(w.file_frame(b"\x01\x02\x00").is_err(), "not a frame");
    for f in &all[10..] {
        w.file_frame(f).unwrap();
    }
    let run = w.finish(false).unwrap();
    assert!(run.is_complete());
    let log = crate::LogReader::read(&run.dir().join(run::LOG_FILE), false).unwrap();
    assert_eq!(log.records, all, "each frame logged once, in arrival order");
}

#[test]
fn a_run_whose_log_lost_frames_is_not_complete_whatever_its_metadata_says() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let run = record(d.path(), &cfg, &v2_run(), |_| {});
    assert_eq!(run.meta.status, RunStatus::Complete);
    let log = run.dir().join(run::LOG_FILE);
    let bytes = std::fs::read(&log).unwrap();
    std::fs::write(&log, &bytes[..bytes.len() - 30]).unwrap();
    let back = Run::open(run.dir()).unwrap();
    assert_eq!(
        back.meta.status,
        RunStatus::Incomplete,
        "derived from the log"
    );
    assert!(back.recovery.is_some());
    let cat = RunCatalog::open(d.path()).unwrap();
    let r = cat.reindex().unwrap();
    assert_eq!(r.incomplete.len(), 1);
    assert!(
        r.incomplete[0]
            .1
            .starts_with("incomplete: 20 of at least 20 blocks")
            && r.incomplete[0].1.contains("torn last record"),
        "{:?}",
        r.incomplete
    );
    let row = &cat.list(&Filter::default()).unwrap()[0];
    assert_eq!(
        (row.status.as_str(), row.blocks, row.blocks_expected),
        ("incomplete", 20, None)
    );
    // The catalog knows when a log changed after it was indexed.
    assert!(cat.stale().unwrap().is_empty());
    std::fs::write(&log, &bytes[..bytes.len() / 2]).unwrap();
    assert_eq!(cat.stale().unwrap(), vec![run.dir().to_owned()]);
}

#[test]
fn a_catalog_of_a_newer_tribo_is_refused_and_one_of_an_older_is_versioned() {
    let d = tempfile::tempdir().unwrap();
    {
        let c = RunCatalog::open(d.path()).unwrap();
        assert!(c.list(&Filter::default()).unwrap().is_empty());
    }
    let conn = rusqlite::Connection::open(d.path().join(catalog::CATALOG_FILE)).unwrap();
    let v: i64 = conn
        .query_row("PRAGMA user_version", [], |r| r.get(0))
        .unwrap();
    assert_eq!(v, catalog::CATALOG_VERSION);
    conn.pragma_update(None, "user_version", catalog::CATALOG_VERSION + 1)
        .unwrap();
    drop(conn);
    let e = RunCatalog::open(d.path()).err().unwrap().to_string();
    assert!(e.contains("newer tribo") && e.contains("--reindex"), "{e}");
}

/// A catalog written before setpoints were catalogued (version 1) cannot tell a heater-off run
/// from one at a setpoint: opening it marks every row stale, and the first refresh rebuilds it from
/// the run folders, so the heater-off run lands in the "heater off" cell and the other at its
/// setpoint (without the rebuild both read as heater off).
#[test]
fn a_catalog_from_before_setpoints_is_rebuilt_on_first_refresh() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    for sp in [None, Some(40.0)] {
        record(d.path(), &cfg, &run_frames(&cfg, 2, 0.02), |m| {
            m.temp_setpoint_c = sp;
            m.temp_c = Some(23.5);
            m.label = Some(format!("{sp:?}"));
        });
    }
    let cat = RunCatalog::open(d.path()).unwrap();
    assert!(
        cat.refresh(false).unwrap().is_some(),
        "new folders: rebuilt"
    );
    assert!(
        cat.refresh(false).unwrap().is_none(),
        "up to date: left alone"
    );
    drop(cat);
    // What a version-1 tribo left: no setpoint column.
    let conn = rusqlite::Connection::open(d.path().join(CATALOG_FILE)).unwrap();
    conn.execute_batch("ALTER TABLE runs DROP COLUMN temp_setpoint_c; PRAGMA user_version = 1;")
        .unwrap();
    drop(conn);
    let cat = RunCatalog::open(d.path()).unwrap();
    assert!(
        cat.list(&Filter::default())
            .unwrap()
            .iter()
            .all(|r| r.temp_setpoint_c.is_none()),
        "the migrated rows do not know their setpoints yet"
    );
    let r = cat.refresh(false).unwrap().expect("stale rows: rebuilt");
    assert_eq!(r.indexed, 2);
    let rows = cat.list(&Filter::default()).unwrap();
    let bins: Vec<Option<Bin>> = rows.iter().map(|r| Bin::of(Axis::Temp, r)).collect();
    assert!(bins.contains(&Some(Bin::HeaterOff)), "{bins:?}");
    assert!(bins.contains(&Some(Bin::SetpointC(40))), "{bins:?}");
}

#[test]
fn a_run_states_the_analog_chain_its_rig_said_and_a_lost_chain_frame_is_a_hole() {
    let d = tempfile::tempdir().unwrap();
    let cfg = Configure::real_rig(0.3);
    let rig = |protocol: u16| {
        move |m: &mut RunMeta| {
            m.device = Some(DeviceMeta {
                firmware: "0.1.0".into(),
                serial: "0123456789abcdef".into(),
                protocol,
                port: "tcp://127.0.0.1:7411".into(),
            })
        }
    };
    // A protocol v3 rig: its chain frame right after the header.
    let mut v3 = v2_run();
    let chain = DeviceMsg::Chain(AnalogChain {
        run_id: 7,
        force_lowpass: LowPass::butterworth(2, 300.0),
    });
    v3.insert(1, encode_vec(100, &chain).unwrap());
    let run = record(d.path(), &cfg, &v3, rig(3));
    assert!(run.is_complete(), "{}", run.completeness().summary());
    assert_eq!(run.chain().map(|c| c.force_lowpass.cutoff_hz), Some(300.0));
    let rec = run.record().unwrap();
    assert_eq!(rec.force_cutoff_hz, Some(300.0));
    let csv = d.path().join("r.csv");
    run.export_csv(&csv).unwrap();
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.contains("# force_cutoff_hz=300\n"), "{text:.300}");
    // Its chain frame lost on the line: the run is not whole (a pull brings the frame).
    let lost: Vec<Vec<u8>> = v3
        .iter()
        .filter(|f| !matches!(kind(f), DeviceMsg::Chain(_)))
        .cloned()
        .collect();
    let r = record(d.path(), &cfg, &lost, rig(3));
    assert_eq!(r.completeness().event_holes, vec![0]);
    assert!(!r.is_complete());
    // A v2 rig never said it: whole, and the record leaves the filter unstated (an analysis fits
    // it); a chain other than the 2-pole Butterworth a record's `force_cutoff_hz` means, too.
    let r = record(d.path(), &cfg, &lost, rig(2));
    assert!(r.is_complete(), "{}", r.completeness().summary());
    assert_eq!(r.record().unwrap().force_cutoff_hz, None);
    let mut one_pole = v2_run();
    let chain = DeviceMsg::Chain(AnalogChain {
        run_id: 7,
        force_lowpass: LowPass::butterworth(1, 300.0),
    });
    one_pole.insert(1, encode_vec(100, &chain).unwrap());
    let r = record(d.path(), &cfg, &one_pole, rig(3));
    assert_eq!(r.chain().map(|c| c.force_lowpass.poles), Some(1));
    assert_eq!(r.record().unwrap().force_cutoff_hz, None);
}
