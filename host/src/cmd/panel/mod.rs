//! `tribo panel`: the rig's front panel, a local web page served by this program.
//!
//! One thread owns the link to the rig ([`rig`]): it polls the rig's status, runs the page's
//! commands through the library calls `tribo run` makes (so the rig's interlocks refuse what they
//! refuse there), holds the rig's lease with a heartbeat while it is connected, and streams a run
//! into the store exactly as `tribo run` does. The pages read the [`state`] it keeps through
//! server-sent events (`/events`): the rig's state every 250 ms, the run's blocks as they arrive,
//! decimated for drawing (min and max over every 32 samples; the store keeps every sample).
//!
//! * One page controls the rig at a time: the first page opened, or the one that takes control
//!   when none does; the others view. `Safe` works from every page, at any time, even during a run.
//! * Every command is a POST with the page's id in an `X-Panel-Client` header (a custom header: a
//!   web site in another tab cannot send it without a CORS pre-flight, which the panel never grants).
//! * The page is served on a loopback address unless `--listen` names another and `--token`
//!   gives the access token the page must then carry (`/?token=…`, kept as a cookie).
//! * The page's HTML, CSS and JavaScript are built into the program: nothing is fetched from the
//!   network.

mod rig;
mod state;

use crate::cmd::run::{abort_flag, LinkArgs};
use anyhow::{bail, Context};
use rig::{Cmd, Reply, RigThread};
use serde_json::{json, Value};
use state::Shared;
use std::io::{Read, Write};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tiny_http::{Header, Method, Request, Response};

const PAGE: &str = include_str!("page.html");
const SCRIPT: &str = include_str!("page.js");

/// How long a controlling page may be silent (its event stream gone) before another takes over.
const CONTROL_STALE: Duration = Duration::from_secs(3);

/// Arguments of `tribo panel`.
#[derive(clap::Args, Debug)]
#[command(after_help = "Examples:
  tribo panel
      the only attached rig (else tcp://127.0.0.1:7411); the page on http://127.0.0.1:7420/
  tribo panel --port tcp://127.0.0.1:7411 --listen 127.0.0.1:0
      a virtual rig (`tribo rig --virtual` in another terminal); the page on a free port
  tribo panel --listen 0.0.0.0:7420 --token S
      served to the lab network: open http://THIS-PC:7420/?token=S

The page shows the rig (connected, serial, state, lease, last fault and reset), the plate's
temperature against its setpoint (\"settled\" within the settling tolerance for the settling
time), the run as it is recorded (displacement with its envelope, velocity, force, ECR; lost blocks
and acquisition gaps shaded), the result (on-board and host fit, as `tribo run` prints it, and a
link to the run's report) and the store's campaign grid (host μ0 per load × temperature, as `tribo
table`). Its controls (heater, configure, arm, release) go to the rig as `tribo run` sends them;
one page controls, the others view; Safe works from every page. Runs are stored as `tribo run`
stores them. GET /api/state gives the page's state as JSON, for scripts.

Closing the panel (Ctrl-C: exit status 130) makes the rig safe; a killed panel leaves it to the
rig's lease, which expires within 3 s.")]
pub struct Args {
    #[command(flatten)]
    pub link: LinkArgs,
    /// Address the page is served on (127.0.0.1:0 picks a free port; the address is printed).
    #[arg(long, default_value = "127.0.0.1:7420")]
    pub listen: SocketAddr,
    /// Access token the page must carry (`http://HOST:PORT/?token=…`); required when --listen is
    /// not a loopback address. Default: $TRIBO_PANEL_TOKEN.
    #[arg(long)]
    pub token: Option<String>,
    /// No progress messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
}

/// What every request handler needs.
#[derive(Clone)]
struct Ctx {
    shared: Arc<Mutex<Shared>>,
    cmds: Sender<(Cmd, Sender<Reply>)>,
    safe: Arc<Mutex<Option<crate::link::hold::SafeHandle>>>,
    abort: Arc<AtomicBool>,
    quit: Arc<AtomicBool>,
    token: Option<String>,
    store: PathBuf,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let token = args
        .token
        .clone()
        .or_else(|| std::env::var("TRIBO_PANEL_TOKEN").ok())
        .filter(|t| !t.is_empty());
    if !args.listen.ip().is_loopback() && token.is_none() {
        return Err(crate::exit::Usage(format!(
            "--listen {} serves the panel beyond this PC: give an access token too (--token SECRET or \
             $TRIBO_PANEL_TOKEN), then open http://THIS-PC:{}/?token=SECRET; or keep the default \
             loopback address",
            args.listen,
            args.listen.port()
        ))
        .into());
    }
    let store = args.link.writable_store()?;
    let server = tiny_http::Server::http(args.listen).map_err(|e| {
        anyhow::anyhow!(
            "cannot serve the panel on {}: {e}; is another panel running? Choose another address with \
             --listen (127.0.0.1:0 picks a free port)",
            args.listen
        )
    })?;
    let addr = server
        .server_addr()
        .to_ip()
        .context("the panel's server has no IP address")?;
    let abort = abort_flag();
    let quit = Arc::new(AtomicBool::new(false));
    let shared = Arc::new(Mutex::new(Shared::new(store.clone())));
    let (tx, rx) = mpsc::channel();
    let safe = Arc::new(Mutex::new(None));
    let run_abort = Arc::new(AtomicBool::new(false));
    let rig = RigThread {
        link: args.link.clone(),
        store: store.clone(),
        shared: shared.clone(),
        cmds: rx,
        safe: safe.clone(),
        abort: run_abort.clone(),
        quit: quit.clone(),
    };
    let rig = std::thread::Builder::new()
        .name("tribo-panel-rig".into())
        .spawn(move || rig.run())
        .context("starting the panel's rig thread")?;
    let ctx = Ctx {
        shared,
        cmds: tx,
        safe,
        abort: run_abort.clone(),
        quit: quit.clone(),
        token: token.clone(),
        store,
    };
    let shown = if addr.ip().is_unspecified() {
        format!("THIS-PC:{}", addr.port())
    } else {
        addr.to_string()
    };
    crate::cmd::run::out(&format!(
        "front panel on http://{shown}/{}\n",
        token
            .as_ref()
            .map_or(String::new(), |t| format!("?token={t}"))
    ))?;
    if !args.quiet {
        eprintln!("open it in a browser; Ctrl-C closes the panel (the rig is made safe)");
    }
    while !abort.load(Ordering::Relaxed) {
        match server.recv_timeout(Duration::from_millis(200)) {
            Ok(Some(req)) => {
                let ctx = ctx.clone();
                let _ = std::thread::Builder::new()
                    .name("tribo-panel-http".into())
                    .spawn(move || handle(req, &ctx));
            }
            Ok(None) => {}
            Err(e) => {
                quit.store(true, Ordering::Relaxed);
                let _ = rig.join();
                bail!("the panel's web server failed: {e}; start `tribo panel` again");
            }
        }
    }
    run_abort.store(true, Ordering::Relaxed);
    quit.store(true, Ordering::Relaxed);
    let _ = rig.join();
    Err(crate::exit::Interrupted("the panel was closed; the rig was made safe".into()).into())
}

fn header(name: &str, value: &str) -> Header {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("a valid header")
}

fn query<'a>(url: &'a str, key: &str) -> Option<&'a str> {
    url.split_once('?')?
        .1
        .split('&')
        .filter_map(|kv| kv.split_once('='))
        .find(|(k, _)| *k == key)
        .map(|(_, v)| v)
}

fn header_value<'a>(req: &'a Request, name: &'static str) -> Option<&'a str> {
    req.headers()
        .iter()
        .find(|h| h.field.equiv(name))
        .map(|h| h.value.as_str())
}

/// Whether the request carries the access token (when there is one).
fn authorised(req: &Request, token: &Option<String>) -> bool {
    let Some(t) = token else { return true };
    if query(req.url(), "token") == Some(t.as_str())
        || header_value(req, "X-Panel-Token") == Some(t)
    {
        return true;
    }
    header_value(req, "Cookie").is_some_and(|c| {
        c.split(';')
            .filter_map(|kv| kv.trim().split_once('='))
            .any(|(k, v)| k == "tribo_panel" && v == t)
    })
}

fn json_response(status: u16, v: &Value) -> Response<std::io::Cursor<Vec<u8>>> {
    Response::from_data(v.to_string().into_bytes())
        .with_status_code(status)
        .with_header(header("Content-Type", "application/json"))
        .with_header(header("Cache-Control", "no-store"))
}

fn lock(s: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    match s.lock() {
        Ok(g) => g,
        Err(p) => p.into_inner(),
    }
}

fn handle(mut req: Request, ctx: &Ctx) {
    if !authorised(&req, &ctx.token) {
        let _ = req.respond(
            Response::from_string(
                "this panel needs its access token: open the address `tribo panel` printed, \
                 http://HOST:PORT/?token=…\n",
            )
            .with_status_code(401),
        );
        return;
    }
    let url = req.url().to_string();
    let path = url.split('?').next().unwrap_or("/").to_string();
    let method = req.method().clone();
    match (&method, path.as_str()) {
        (Method::Get, "/") => {
            let mut r = Response::from_string(PAGE)
                .with_header(header("Content-Type", "text/html; charset=utf-8"))
                .with_header(header("Cache-Control", "no-store"));
            if let Some(t) = &ctx.token {
                r = r.with_header(header(
                    "Set-Cookie",
                    &format!("tribo_panel={t}; Path=/; HttpOnly; SameSite=Strict"),
                ));
            }
            let _ = req.respond(r);
        }
        (Method::Get, "/panel.js") => {
            let _ = req.respond(
                Response::from_string(SCRIPT)
                    .with_header(header("Content-Type", "text/javascript; charset=utf-8")),
            );
        }
        (Method::Get, "/events") => {
            let client = query(&url, "client").unwrap_or("").to_string();
            events(req, ctx, client);
        }
        (Method::Get, "/api/state") => {
            let v = lock(&ctx.shared).to_json(None);
            let _ = req.respond(json_response(200, &v));
        }
        (Method::Get, p) if p.starts_with("/report/") => report_file(req, &ctx.store, p),
        (Method::Post, p) if p.starts_with("/api/") => {
            let name = p.trim_start_matches("/api/").to_string();
            let client = header_value(&req, "X-Panel-Client").map(str::to_string);
            let mut body = String::new();
            let _ = req.as_reader().take(64 * 1024).read_to_string(&mut body);
            let (status, v) = post(ctx, &name, client.as_deref(), &body);
            let _ = req.respond(json_response(status, &v));
        }
        _ => {
            let _ = req.respond(Response::from_string("not found\n").with_status_code(404));
        }
    }
}

/// A command from a page: `(HTTP status, {"ok", "text"})`.
fn post(ctx: &Ctx, name: &str, client: Option<&str>, body: &str) -> (u16, Value) {
    let answer = |status: u16, ok: bool, text: String| (status, json!({"ok": ok, "text": text}));
    let Some(client) = client.filter(|c| !c.is_empty()) else {
        return answer(
            400,
            false,
            "a command needs the page's id in the X-Panel-Client header (use the panel's page)"
                .into(),
        );
    };
    if name == "safe" {
        // From any page, at any time, whatever the rig thread is doing.
        ctx.abort.store(true, Ordering::Relaxed);
        let handle = ctx.safe.lock().ok().and_then(|h| h.clone());
        let (ok, text) = match handle {
            Some(h) if h.send_safe() => (true, "safe: heater and magnet off (sent to the rig)".to_string()),
            Some(_) => (false, "safe: the link did not take it; the rig goes safe by itself when its lease runs out".to_string()),
            None => (false, "safe: no rig is connected; a rig left heating goes safe by itself when its lease runs out".to_string()),
        };
        lock(&ctx.shared).say(ok, text.clone());
        return answer(if ok { 200 } else { 503 }, ok, text);
    }
    {
        let mut s = lock(&ctx.shared);
        let now = Instant::now();
        let free = s
            .controller
            .as_ref()
            .is_none_or(|(_, seen)| now.duration_since(*seen) > CONTROL_STALE);
        if name == "claim" {
            if free || s.controller.as_ref().is_some_and(|(id, _)| id == client) {
                s.controller = Some((client.to_string(), now));
                s.changed();
                return answer(200, true, "this page controls the rig".into());
            }
            return answer(
                409,
                false,
                "another page controls the rig: this one views (close the other page to take control here)".into(),
            );
        }
        if s.controller.as_ref().is_none_or(|(id, _)| id != client) {
            return answer(
                409,
                false,
                format!(
                    "{name}: refused, another page controls the rig and this one only views (Safe works from any page)"
                ),
            );
        }
        if let Some(b) = &s.busy {
            return answer(
                409,
                false,
                format!(
                    "{name}: refused while {b}: wait for the run to end (Safe works at any time)"
                ),
            );
        }
    }
    let args: Value = serde_json::from_str(body).unwrap_or(Value::Null);
    let f32_of = |k: &str| args.get(k).and_then(Value::as_f64).map(|v| v as f32);
    let cmd = match name {
        "heater" => match (f32_of("setpoint_c"), f32_of("ramp_c_per_min")) {
            (Some(setpoint_c), Some(ramp_c_per_min)) => Cmd::Heater {
                setpoint_c,
                ramp_c_per_min,
            },
            _ => {
                return answer(
                    400,
                    false,
                    "heater: give a setpoint (°C) and a ramp (°C/min) as numbers".into(),
                )
            }
        },
        "heater-off" => Cmd::HeaterOff,
        "configure" => match (
            f32_of("load_n"),
            args.get("rate_hz").and_then(Value::as_u64),
            f32_of("max_duration_s"),
        ) {
            (Some(load_n), Some(rate), Some(max_duration_s)) => Cmd::Configure {
                load_n,
                rate_hz: rate.min(u32::MAX as u64) as u32,
                max_duration_s,
            },
            _ => return answer(
                400,
                false,
                "configure: give the load (N), the rate (S/s) and the longest run (s) as numbers"
                    .into(),
            ),
        },
        "arm" => Cmd::Arm,
        "release" => Cmd::Release,
        _ => {
            return answer(
                404,
                false,
                format!(
                    "no command {name:?}: heater, heater-off, configure, arm, release, safe, claim"
                ),
            )
        }
    };
    let (tx, rx) = mpsc::channel();
    if ctx.cmds.send((cmd, tx)).is_err() {
        return answer(503, false, "the panel is closing".into());
    }
    let r = rx
        .recv_timeout(Duration::from_secs(15))
        .unwrap_or_else(|_| {
            Err(format!(
                "{name}: no answer from the rig thread in 15 s; check the rig line"
            ))
        });
    let (ok, text) = match r {
        Ok(t) => (true, t),
        Err(t) => (false, t),
    };
    lock(&ctx.shared).say(ok, text.clone());
    answer(if ok { 200 } else { 409 }, ok, text)
}

/// The page's event stream: the state when it changed (at most every 250 ms), the run's new
/// blocks every 100 ms, and a comment every few seconds so that a closed page is noticed.
fn events(req: Request, ctx: &Ctx, client: String) {
    {
        let mut s = lock(&ctx.shared);
        let now = Instant::now();
        let free = s
            .controller
            .as_ref()
            .is_none_or(|(_, seen)| now.duration_since(*seen) > CONTROL_STALE);
        if free && !client.is_empty() {
            s.controller = Some((client.clone(), now));
            s.changed();
        }
    }
    let mut w = req.into_writer();
    let head = "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\n\
                Connection: close\r\nX-Accel-Buffering: no\r\n\r\n";
    if w.write_all(head.as_bytes())
        .and_then(|_| w.flush())
        .is_err()
    {
        return;
    }
    let mut sent_version = 0;
    let mut sent_run: Option<u32> = None;
    let mut sent_blocks = 0;
    let mut last_state = Instant::now() - Duration::from_secs(1);
    let mut last_write = Instant::now();
    while !ctx.quit.load(Ordering::Relaxed) {
        let mut out = String::new();
        {
            let mut s = lock(&ctx.shared);
            if let Some((id, seen)) = s.controller.as_mut() {
                if *id == client {
                    *seen = Instant::now();
                }
            }
            if s.version != sent_version && last_state.elapsed() >= Duration::from_millis(250) {
                sent_version = s.version;
                last_state = Instant::now();
                out.push_str(&format!(
                    "event: state\ndata: {}\n\n",
                    s.to_json(Some(&client))
                ));
            }
            if let Some(t) = &s.trace {
                if sent_run != Some(t.run_id) {
                    sent_run = Some(t.run_id);
                    sent_blocks = 0;
                }
                if t.blocks.len() > sent_blocks {
                    out.push_str(&format!(
                        "event: trace\ndata: {}\n\n",
                        t.blocks_json(sent_blocks)
                    ));
                    sent_blocks = t.blocks.len();
                }
            }
        }
        if out.is_empty() && last_write.elapsed() > Duration::from_secs(2) {
            out.push_str(": still here\n\n");
        }
        if !out.is_empty() {
            if w.write_all(out.as_bytes()).and_then(|_| w.flush()).is_err() {
                break;
            }
            last_write = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    // The page went away: if it controlled the rig, control is free for another page.
    let mut s = lock(&ctx.shared);
    if s.controller.as_ref().is_some_and(|(id, _)| *id == client) {
        s.controller = None;
        s.changed();
    }
}

/// A file of a run's report: `/report/RUN/FILE`, from `STORE/RUN/report/FILE`.
fn report_file(req: Request, store: &Path, path: &str) {
    let mut parts = path.trim_start_matches("/report/").splitn(2, '/');
    let (Some(run), Some(file)) = (parts.next(), parts.next()) else {
        let _ = req.respond(Response::from_string("not found\n").with_status_code(404));
        return;
    };
    let safe =
        |s: &str| !s.is_empty() && !s.contains("..") && !s.contains('\\') && !s.starts_with('/');
    if !safe(run) || run.contains('/') || !safe(file) {
        let _ = req.respond(Response::from_string("not found\n").with_status_code(404));
        return;
    }
    let p = store.join(run).join("report").join(file);
    let kind = match p.extension().and_then(|e| e.to_str()) {
        Some("html") => "text/html; charset=utf-8",
        Some("svg") => "image/svg+xml",
        Some("png") => "image/png",
        Some("csv") | Some("txt") => "text/plain; charset=utf-8",
        _ => "application/octet-stream",
    };
    match std::fs::read(&p) {
        Ok(bytes) => {
            let _ =
                req.respond(Response::from_data(bytes).with_header(header("Content-Type", kind)));
        }
        Err(_) => {
            let _ = req.respond(
                Response::from_string("no such report file (is the report still being written?)\n")
                    .with_status_code(404),
            );
        }
    }
}
