//! Shared by the host tests: a virtual rig served on a local TCP port (no pseudo-terminal, on every
//! system), and run plans.
#![allow(dead_code)]

use std::net::TcpListener;
use std::sync::atomic::AtomicBool;
use std::time::Duration;
use tribo::link::session::{record_run, Outcome, RunPlan};
use tribo::link::{Address, Link};
use tribo_rig::{ServeOptions, TcpRig, VirtualRig, VirtualRigConfig};
use tribo_wire::{Configure, DeviceInfo};

/// A virtual rig served on a local TCP port; it stops when this is dropped. Derefs to its address.
pub struct RigOnTcp {
    addr: Address,
    _rig: TcpRig,
}

impl RigOnTcp {
    /// Serves `rig` on a free local port.
    pub fn serve(rig: VirtualRig, opts: ServeOptions) -> RigOnTcp {
        let l = TcpListener::bind("127.0.0.1:0").expect("a local port");
        let rig = TcpRig::spawn(rig, l, opts, |_| {}).expect("serving the virtual rig");
        RigOnTcp {
            addr: Address::from(rig.addr()),
            _rig: rig,
        }
    }

    /// Keeps a rig started elsewhere (e.g. by `tribo::virtual_rig::VirtualArgs::listen`).
    pub fn from(rig: TcpRig) -> RigOnTcp {
        RigOnTcp {
            addr: Address::from(rig.addr()),
            _rig: rig,
        }
    }
}

impl std::ops::Deref for RigOnTcp {
    type Target = Address;
    fn deref(&self) -> &Address {
        &self.addr
    }
}

/// A virtual rig with a Coulomb–viscous contact, served on a local TCP port at `speed`× real time
/// (it stops when the first value is dropped). Returns the rig and the (μ0, μ1) a Coulomb–viscous
/// fit should find.
pub fn virtual_rig(mu0: f64, mu1: f64, seed: u64, speed: f64) -> (RigOnTcp, (f64, f64)) {
    let cfg = VirtualRigConfig {
        law: tribo_physics::FrictionLaw::coulomb_viscous(mu0, mu1),
        seed,
        ..Default::default()
    };
    let rig = VirtualRig::new(cfg).expect("valid virtual rig");
    let truth = rig.truth().expect("Coulomb–viscous truth");
    let opts = ServeOptions {
        speed,
        max_wait: Duration::from_millis(2),
        ..Default::default()
    };
    (RigOnTcp::serve(rig, opts), truth)
}

pub fn connect(port: &Address) -> (Link, DeviceInfo) {
    let mut link = Link::open(port).expect("connect to the virtual rig");
    let info = link.hello().expect("hello");
    (link, info)
}

/// Connects to `port` and records one run of [`plan`] into `store`, without abort or progress.
pub fn record_plain_run(port: &Address, store: &std::path::Path) -> Outcome {
    let (mut link, info) = connect(port);
    record_run(
        &mut link,
        &info,
        store,
        &plan(),
        &AtomicBool::new(false),
        &mut |_| {},
    )
    .expect("a complete run")
}

/// The thesis's rig at 0.3 N (the virtual rig's knob), runs of at most 8 s.
pub fn plan() -> RunPlan {
    let mut c = Configure::real_rig(0.3);
    c.max_duration_s = 8.0;
    RunPlan::new(c)
}

/// Asserts the thesis's stated precision of the method: μ0 ± 0.001, μ1 ± 0.0002.
pub fn assert_close(what: &str, mu0: f64, mu1: f64, truth: (f64, f64)) {
    assert!(
        (mu0 - truth.0).abs() < 1e-3,
        "{what}: μ0 {mu0} vs {}",
        truth.0
    );
    assert!(
        (mu1 - truth.1).abs() < 2e-4,
        "{what}: μ1 {mu1} vs {}",
        truth.1
    );
}

/// Asserts a stored run holds every block of the run, in place: complete, nothing missing, as many
/// blocks and samples as the rig's end frame says, sample times contiguous.
pub fn assert_lossless(run: &tribo_store::Run) {
    assert!(
        run.is_complete(),
        "missing blocks {:?}",
        run.missing_blocks()
    );
    let end = run.end().expect("end frame");
    assert_eq!(run.block_count() as u32, end.blocks);
    let s = run.samples_si().unwrap();
    assert_eq!(s.len() as u32, end.samples);
    let dt = 1.0 / run.config().sample_rate_hz as f64;
    for (i, t) in s.t.iter().enumerate() {
        assert!((t - i as f64 * dt).abs() < 1e-9, "sample {i} at {t}");
    }
}

/// Two ends of a local TCP connection: a line to play the rig on in tests.
pub fn stream_pair() -> (std::net::TcpStream, std::net::TcpStream) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let a = std::net::TcpStream::connect(l.local_addr().unwrap()).unwrap();
    let (b, _) = l.accept().unwrap();
    (a, b)
}
