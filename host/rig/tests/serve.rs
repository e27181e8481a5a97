//! How the virtual rig is served to a host: over one stream, to successive TCP connections (the rig
//! living on between them, one host at a time), and in-process.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tribo_rig::{in_process, serve, HostEvent, ServeOptions, TcpRig, VirtualRig, VirtualRigConfig};
use tribo_wire::frame::{decode_one, encode_vec};
use tribo_wire::*;

type Frames = Vec<(Vec<u8>, Frame<DeviceMsg>)>;

/// Two ends of a loopback TCP connection.
fn stream_pair() -> (TcpStream, TcpStream) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let a = TcpStream::connect(l.local_addr().unwrap()).unwrap();
    let (b, _) = l.accept().unwrap();
    (a, b)
}

/// Reads frames from a stream until `stop` says so, the stream ends, or 60 s pass.
fn read_frames(s: &mut impl Read, stop: impl Fn(&[Frame<DeviceMsg>]) -> bool) -> Frames {
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut buf = Vec::new();
    let mut frames: Frames = Vec::new();
    let mut chunk = [0u8; 8192];
    while Instant::now() < deadline {
        match s.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(_) => {} // read timeout
        }
        while let Some(p) = buf.iter().position(|&b| b == 0) {
            let f: Vec<u8> = buf.drain(..=p).collect();
            frames.push((f.clone(), decode_one(&f).expect("valid frame")));
        }
        let msgs: Vec<Frame<DeviceMsg>> = frames.iter().map(|f| f.1.clone()).collect();
        if stop(&msgs) {
            break;
        }
    }
    frames
}

fn ended(m: &[Frame<DeviceMsg>]) -> bool {
    m.iter().any(|f| matches!(f.msg, DeviceMsg::RunEnded(_)))
}

fn is_block(m: &DeviceMsg) -> bool {
    matches!(m, DeviceMsg::Samples(_) | DeviceMsg::Packed(_))
}

fn hello() -> Vec<u8> {
    encode_vec(
        1,
        &HostMsg::Hello {
            protocol: PROTOCOL_VERSION,
        },
    )
    .unwrap()
}

/// Hello, configure a run of at most `max_s` device seconds, arm: the bytes a host sends.
fn start_commands(max_s: f32) -> Vec<u8> {
    let mut c = Configure::real_rig(0.3);
    c.max_duration_s = max_s;
    let mut bytes = hello();
    bytes.extend(encode_vec(2, &HostMsg::Configure(c)).unwrap());
    bytes.extend(encode_vec(3, &HostMsg::Arm).unwrap());
    bytes
}

#[test]
fn serve_over_a_stream_survives_a_pulled_cable_and_replays_the_run() {
    let mut rig = VirtualRig::new(VirtualRigConfig::default()).unwrap();
    let opts = ServeOptions {
        speed: 8.0,
        ..Default::default()
    };
    // First connection: a whole run.
    let (mut host, dev) = stream_pair();
    host.set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let first = std::thread::scope(|s| {
        let r = dev.try_clone().unwrap();
        let h = s.spawn(|| serve(&mut rig, r, dev, &opts));
        host.write_all(&start_commands(5.0)).unwrap();
        std::thread::sleep(Duration::from_millis(60));
        host.write_all(&encode_vec(4, &HostMsg::Release).unwrap())
            .unwrap();
        let frames = read_frames(&mut host, ended);
        // Pull the cable.
        host.shutdown(std::net::Shutdown::Both).unwrap();
        drop(host);
        assert!(
            h.join().unwrap().is_ok(),
            "serve must return cleanly at end of file"
        );
        frames
    });
    let run: Vec<&(Vec<u8>, Frame<DeviceMsg>)> =
        first.iter().filter(|f| f.1.msg.is_run_frame()).collect();
    assert!(matches!(first[0].1.msg, DeviceMsg::Hello(_)));
    assert!(run.len() > 20, "{} run frames", run.len());
    let DeviceMsg::RunStarted(header) = run[0].1.msg else {
        panic!("run starts with its header")
    };
    // Second connection on the same rig: pull from block 7, get the very same bytes.
    let (mut host, dev) = stream_pair();
    host.set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let again = std::thread::scope(|s| {
        let r = dev.try_clone().unwrap();
        let h = s.spawn(|| serve(&mut rig, r, dev, &opts));
        host.write_all(
            &encode_vec(
                10,
                &HostMsg::Pull {
                    run_id: header.run_id,
                    from_block: 7,
                },
            )
            .unwrap(),
        )
        .unwrap();
        let frames = read_frames(&mut host, ended);
        host.shutdown(std::net::Shutdown::Both).unwrap();
        drop(host);
        assert!(h.join().unwrap().is_ok());
        frames
    });
    assert!(matches!(again[0].1.msg, DeviceMsg::Ack { seq: 10 }));
    let got: Vec<&Vec<u8>> = again[1..].iter().map(|f| &f.0).collect();
    // The header, then the live order from just after block 6 (the events between blocks 6 and 7
    // come along in their place).
    let after = run
        .iter()
        .rposition(|f| matches!(&f.1.msg, DeviceMsg::Packed(b) if b.block < 7))
        .expect("blocks 0..7 were sent")
        + 1;
    let want: Vec<&Vec<u8>> = run[..1].iter().chain(&run[after..]).map(|f| &f.0).collect();
    assert_eq!(got, want);
}

#[test]
fn serve_refuses_options_under_which_the_rig_would_never_advance() {
    let mut rig = VirtualRig::new(VirtualRigConfig::default()).unwrap();
    for speed in [0.0, -1.0, f64::NAN] {
        let opts = ServeOptions {
            speed,
            ..Default::default()
        };
        let r = serve(&mut rig, std::io::empty(), std::io::sink(), &opts);
        assert_eq!(
            r.map_err(|e| e.kind()),
            Err(std::io::ErrorKind::InvalidInput)
        );
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let rig = VirtualRig::new(VirtualRigConfig::default()).unwrap();
        assert!(TcpRig::spawn(rig, l, opts, |_| {}).is_err());
    }
    for after in [-0.1, f64::NAN, f64::INFINITY] {
        let opts = ServeOptions {
            button_after_s: Some(after),
            ..Default::default()
        };
        assert!(opts.validate().is_err(), "button after {after} s accepted");
    }
    // A fast serve of a closed stream returns at once, cleanly.
    let opts = ServeOptions {
        speed: f64::INFINITY,
        ..Default::default()
    };
    assert!(serve(&mut rig, std::io::empty(), std::io::sink(), &opts).is_ok());
}

/// Connects to a TCP rig with a read timeout.
/// A default virtual rig served on a free local port, and what happens to its connections.
fn tcp_rig(opts: ServeOptions) -> (TcpRig, mpsc::Receiver<HostEvent>) {
    let rig = VirtualRig::new(VirtualRigConfig::default()).unwrap();
    let (etx, erx) = mpsc::channel();
    let tcp = TcpRig::spawn(
        rig,
        TcpListener::bind("127.0.0.1:0").unwrap(),
        opts,
        move |e| {
            let _ = etx.send(e);
        },
    )
    .unwrap();
    (tcp, erx)
}

fn connect(rig: &TcpRig) -> TcpStream {
    let s = TcpStream::connect(rig.addr()).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    s
}

#[test]
fn a_tcp_rig_runs_on_between_hosts_and_the_next_host_pulls_the_whole_run() {
    let (tcp, erx) = tcp_rig(ServeOptions {
        speed: 8.0,
        ..Default::default()
    });

    // Host A: starts a run of at most 1 s (all of it fits the rig's memory), takes a few blocks
    // and goes.
    let mut a = connect(&tcp);
    a.write_all(&start_commands(1.0)).unwrap();
    std::thread::sleep(Duration::from_millis(60));
    a.write_all(&encode_vec(4, &HostMsg::Release).unwrap())
        .unwrap();
    let seen = read_frames(&mut a, |m| {
        m.iter().filter(|f| is_block(&f.msg)).count() >= 3
    });
    drop(a);
    let header = seen
        .iter()
        .find(|f| matches!(f.1.msg, DeviceMsg::RunStarted(_)))
        .expect("the run started")
        .clone();
    let DeviceMsg::RunStarted(h) = header.1.msg else {
        unreachable!()
    };
    assert!(!ended(
        &seen.iter().map(|f| f.1.clone()).collect::<Vec<_>>()
    ));
    // Nobody connected for 0.4 s wall, 3.2 s device: the run ends meanwhile.
    std::thread::sleep(Duration::from_millis(400));

    // Host B: the rig is past its run at once, and hands it over whole.
    let mut b = connect(&tcp);
    let mut ask = encode_vec(1, &HostMsg::Status).unwrap();
    ask.extend(
        encode_vec(
            2,
            &HostMsg::Pull {
                run_id: h.run_id,
                from_block: 0,
            },
        )
        .unwrap(),
    );
    b.write_all(&ask).unwrap();
    // What the rig still had to send of the live stream may come first; the pulled run follows the
    // pull's Ack.
    let pull_acked = |m: &[Frame<DeviceMsg>]| {
        m.iter()
            .position(|f| matches!(f.msg, DeviceMsg::Ack { seq: 2 }))
    };
    let got = read_frames(&mut b, |m| pull_acked(m).is_some_and(|i| ended(&m[i..])));
    let status = got
        .iter()
        .find_map(|f| match f.1.msg {
            DeviceMsg::Status(s) => Some(s),
            _ => None,
        })
        .expect("status answered");
    assert_eq!(status.run_id, h.run_id);
    assert!(
        !matches!(status.state, RigState::Running | RigState::Armed),
        "the rig's clock ran while no host was connected: {:?}",
        status.state
    );
    let msgs: Vec<Frame<DeviceMsg>> = got.iter().map(|f| f.1.clone()).collect();
    let acked = pull_acked(&msgs).expect("the pull was acknowledged");
    let run: Vec<&(Vec<u8>, Frame<DeviceMsg>)> = got[acked..]
        .iter()
        .filter(|f| f.1.msg.is_run_frame())
        .collect();
    assert_eq!(run[0].0, header.0, "the same header, byte for byte");
    let blocks: Vec<&Vec<u8>> = run
        .iter()
        .filter(|f| is_block(&f.1.msg))
        .map(|f| &f.0)
        .collect();
    let DeviceMsg::RunEnded(end) = run.last().unwrap().1.msg else {
        panic!("the pull ends with the run's end")
    };
    assert_eq!(blocks.len() as u32, end.blocks, "every block of the run");
    let a_blocks: Vec<&Vec<u8>> = seen
        .iter()
        .filter(|f| is_block(&f.1.msg))
        .map(|f| &f.0)
        .collect();
    assert_eq!(
        &blocks[..a_blocks.len()],
        &a_blocks[..],
        "what A got, B gets again"
    );
    drop(b);
    drop(tcp);
    let events: Vec<HostEvent> = erx.try_iter().collect();
    assert!(
        matches!(
            events.as_slice(),
            [
                HostEvent::Connected(_),
                HostEvent::Disconnected(..),
                HostEvent::Connected(_),
                ..
            ]
        ),
        "{events:?}"
    );
}

#[test]
fn a_tcp_rig_serves_one_host_at_a_time_and_turns_a_second_away() {
    let (tcp, erx) = tcp_rig(ServeOptions::default());
    let hello_answered = |s: &mut TcpStream| {
        s.write_all(&hello()).unwrap();
        read_frames(s, |m| {
            m.iter().any(|f| matches!(f.msg, DeviceMsg::Hello(_)))
        })
        .iter()
        .any(|f| matches!(f.1.msg, DeviceMsg::Hello(_)))
    };
    let mut a = connect(&tcp);
    assert!(hello_answered(&mut a));
    // A second host while A is served: closed within the hand-over time, never answered.
    let mut b = connect(&tcp);
    b.write_all(&hello()).unwrap();
    let t0 = Instant::now();
    let mut buf = [0u8; 64];
    let n = loop {
        match b.read(&mut buf) {
            Ok(n) => break n,
            Err(_) if t0.elapsed() < Duration::from_secs(10) => continue,
            Err(e) => panic!("the second host is left hanging: {e}"),
        }
    };
    assert_eq!(n, 0, "turned away without an answer");
    // A is still served.
    assert!(hello_answered(&mut a));
    // Once A goes, the next host is served.
    drop(a);
    let mut c = connect(&tcp);
    assert!(hello_answered(&mut c));
    drop(c);
    drop(tcp);
    let events: Vec<HostEvent> = erx.try_iter().collect();
    let kinds: Vec<&str> = events
        .iter()
        .map(|e| match e {
            HostEvent::Connected(_) => "connected",
            HostEvent::Disconnected(..) => "disconnected",
            HostEvent::Refused(_) => "refused",
        })
        .collect();
    assert_eq!(
        kinds[..4],
        ["connected", "refused", "disconnected", "connected"],
        "{events:?}"
    );
}

#[test]
fn two_hosts_knocking_at_once_are_served_in_turn_and_a_stopped_rig_is_handed_back() {
    let (tcp, erx) = tcp_rig(ServeOptions::default());
    let addr = tcp.addr();
    // Both knock before the rig looks (it looks every few milliseconds), each saying hello.
    let mut hosts = vec![connect(&tcp), connect(&tcp)];
    for h in &mut hosts {
        h.write_all(&hello()).unwrap();
    }
    let said_hello =
        |m: &[Frame<DeviceMsg>]| m.iter().any(|f| matches!(f.msg, DeviceMsg::Hello(_)));
    let Ok(HostEvent::Connected(first)) = erx.recv_timeout(Duration::from_secs(10)) else {
        panic!("nobody served")
    };
    let i = hosts
        .iter()
        .position(|h| h.local_addr().unwrap() == first)
        .expect("one of the two");
    let mut served = hosts.remove(i);
    let mut waiting = hosts.pop().unwrap();
    assert!(said_hello(
        &read_frames(&mut served, said_hello)
            .into_iter()
            .map(|f| f.1)
            .collect::<Vec<_>>()
    ));
    // The first goes well within the hand-over time: the second, waiting, is served next.
    drop(served);
    let got: Vec<Frame<DeviceMsg>> = read_frames(&mut waiting, said_hello)
        .into_iter()
        .map(|f| f.1)
        .collect();
    assert!(said_hello(&got), "the second host was turned away: {got:?}");
    drop(waiting);
    let rig = tcp.stop();
    // Handed back, having run on; nobody serves it any more.
    assert!(rig.now_us() > 0);
    assert!(TcpStream::connect(addr).is_err(), "still listening");
    let events: Vec<HostEvent> = erx.try_iter().collect();
    assert!(
        !events.iter().any(|e| matches!(e, HostEvent::Refused(_))),
        "{events:?}"
    );
}

#[test]
fn an_in_process_rig_answers_and_stops_with_its_host() {
    let rig = VirtualRig::new(VirtualRigConfig::default()).unwrap();
    let (mut from_rig, mut to_rig, thread) = in_process(rig, ServeOptions::default()).unwrap();
    to_rig.write_all(&hello()).unwrap();
    let frames = read_frames(&mut from_rig, |m| {
        m.iter().any(|f| matches!(f.msg, DeviceMsg::Hello(_)))
    });
    let Some(DeviceMsg::Hello(info)) = frames
        .iter()
        .map(|f| f.1.msg.clone())
        .find(|m| matches!(m, DeviceMsg::Hello(_)))
    else {
        panic!("no hello: {frames:?}")
    };
    assert_eq!(info.protocol, PROTOCOL_VERSION);
    // The host lets go: the rig's thread ends, and the host's reader sees the end of the stream.
    drop(to_rig);
    assert!(thread.join().unwrap().is_ok());
    let mut rest = Vec::new();
    from_rig.read_to_end(&mut rest).unwrap();
}
