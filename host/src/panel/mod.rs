//! The rig's front panel (`tribo panel`), a local web page served by this program.
//!
//! One thread owns the link to the rig (`link_thread`): it polls the rig's status, runs the page's
//! commands through the library calls `tribo run` makes (so the rig's interlocks refuse what they
//! refuse there), holds the rig's lease with a heartbeat while it is connected, and streams a run
//! into the store exactly as `tribo run` does. The pages read the `state` it keeps through
//! server-sent events (`/events`): the rig's state every 250 ms, the run's blocks as they arrive,
//! decimated for drawing (min and max over every 32 samples; the store keeps every sample).
//!
//! * One page controls the rig at a time: the first page opened, or the one that takes control
//!   when none does; the others view. `Safe` works from every page, at any time, even during a run.
//! * The panel answers only to itself: every request's `Host` (and `Origin`, when a browser sends
//!   one) must name the address it listens on (or a name given with `--listen NAME:PORT`,
//!   `localhost` on loopback), so a page of another site — one whose name was rebound to
//!   127.0.0.1 included — is refused (403) before anything else.
//! * Every request but the page and its script carries the access token (a cookie the page gets,
//!   an `X-Panel-Token` header, or `?token=`), on loopback too: `--token`, else one made at start.
//!   On loopback without `--token` the page itself is served without it (and sets the cookie).
//! * Every command is a POST with the page's id in an `X-Panel-Client` header (a custom header: a
//!   web site in another tab cannot send it without a CORS pre-flight, which the panel never grants).
//! * The page is served on a loopback address unless `--listen` names another and `--token`
//!   gives the access token the page must then carry (`/?token=…`, kept as a cookie).
//! * A release while the plate is still settling (a setpoint set, not yet within the tolerance for
//!   the settling time) is refused until the page confirms it (`tribo run` waits instead).
//! * The page's HTML, CSS and JavaScript are built into the program: nothing is fetched from the
//!   network.

mod link_thread;
mod state;

use crate::link::args::LinkArgs;
use crate::ui::abort_flag;
use anyhow::{bail, Context};
use link_thread::{Cmd, LinkThread, Reply};
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

/// What every request handler needs.
#[derive(Clone)]
struct Ctx {
    shared: Arc<Mutex<Shared>>,
    cmds: Sender<(Cmd, Sender<Reply>)>,
    safe: Arc<Mutex<Option<crate::link::hold::SafeHandle>>>,
    abort: Arc<AtomicBool>,
    quit: Arc<AtomicBool>,
    /// The access token every request but the page carries (given, or made at start).
    token: String,
    /// The page itself needs the token too (it was given: `--token`, `$TRIBO_PANEL_TOKEN`).
    page_needs_token: bool,
    /// Where the panel listens and the names it answers to.
    origin: Origin,
    store: PathBuf,
}

/// The address the panel is served on and the names a request may call it by: `Host` and
/// `Origin` must name it, or the request comes from a page of another site (a DNS name rebound
/// to this address included) and is refused.
#[derive(Clone, Debug)]
struct Origin {
    addr: SocketAddr,
    names: Vec<String>,
}

impl Origin {
    /// Whether `host` (a `Host` header's value: `NAME[:PORT]`, `[V6][:PORT]`) names this panel.
    fn allows(&self, host: &str) -> bool {
        let host = host.trim().to_ascii_lowercase();
        let (name, port) = if let Some(rest) = host.strip_prefix('[') {
            match rest.split_once(']') {
                Some((v6, tail)) => (v6.to_string(), tail.strip_prefix(':').map(str::to_string)),
                None => return false,
            }
        } else {
            match host.rsplit_once(':') {
                Some((n, p)) => (n.to_string(), Some(p.to_string())),
                None => (host.clone(), None),
            }
        };
        let port_ok = match port {
            Some(p) => p.parse::<u16>().is_ok_and(|p| p == self.addr.port()),
            None => self.addr.port() == 80,
        };
        if !port_ok || name.is_empty() {
            return false;
        }
        let ip = self.addr.ip();
        match name.parse::<std::net::IpAddr>() {
            Ok(a) => a == ip || ip.is_unspecified() || (ip.is_loopback() && a.is_loopback()),
            Err(_) => (ip.is_loopback() && name == "localhost") || self.names.contains(&name),
        }
    }

    /// Whether the request's `Host` and `Origin` (when there is one) name this panel.
    fn check(&self, req: &Request) -> Result<(), String> {
        let Some(host) = header_value(req, "Host") else {
            return Err("no Host header".into());
        };
        if !self.allows(host) {
            return Err(format!("Host {host:?} is not this panel's address"));
        }
        if let Some(origin) = header_value(req, "Origin") {
            let ok = origin
                .strip_prefix("http://")
                .is_some_and(|h| !h.contains('/') && self.allows(h));
            if !ok {
                return Err(format!(
                    "a page of another origin ({origin}) may not use this panel"
                ));
            }
        }
        Ok(())
    }
}

/// `--listen`: `IP:PORT`, or `NAME:PORT` resolved here (the name is then one the panel answers
/// to). A usage error (status 2) when it is neither.
fn parse_listen(listen: &str) -> anyhow::Result<(SocketAddr, Option<String>)> {
    if let Ok(a) = listen.parse::<SocketAddr>() {
        return Ok((a, None));
    }
    let usage = |why: String| -> anyhow::Error {
        crate::exit::Usage(format!(
            "--listen {listen}: {why}; write IP:PORT or NAME:PORT (127.0.0.1:0 picks a free port)"
        ))
        .into()
    };
    let Some((name, port)) = listen.rsplit_once(':') else {
        return Err(usage("no port".into()));
    };
    if port.parse::<u16>().is_err() {
        return Err(usage(format!(
            "the port {port:?} is not a number from 0 to 65535"
        )));
    }
    use std::net::ToSocketAddrs;
    let addrs: Vec<SocketAddr> = listen
        .to_socket_addrs()
        .map_err(|e| usage(format!("the name {name:?} does not resolve ({e})")))?
        .collect();
    let a = addrs
        .iter()
        .find(|a| a.is_ipv4())
        .or(addrs.first())
        .copied()
        .ok_or_else(|| usage(format!("the name {name:?} has no address")))?;
    Ok((a, Some(name.to_ascii_lowercase())))
}

/// A token made at start when none is given: 128 bits from the standard library's per-process
/// random hash keys (no other source is needed for a token that lives as long as the panel).
fn fresh_token() -> String {
    use std::hash::{BuildHasher, Hasher};
    let part = |salt: u64| {
        let mut h = std::collections::hash_map::RandomState::new().build_hasher();
        h.write_u64(salt);
        h.write_u128(
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos()),
        );
        h.finish()
    };
    format!("{:016x}{:016x}", part(1), part(std::process::id() as u64))
}

/// Serves the panel on `listen` (`IP:PORT` or `NAME:PORT`) for the rig `link` reaches, until
/// Ctrl-C (an [`crate::exit::Interrupted`] error). The access token: `token`, else
/// `$TRIBO_PANEL_TOKEN`, else one made here (required beyond loopback).
pub fn serve(
    link: &LinkArgs,
    listen: &str,
    token: Option<String>,
    quiet: bool,
) -> anyhow::Result<()> {
    let listen_arg = listen;
    let token = token
        .or_else(|| std::env::var("TRIBO_PANEL_TOKEN").ok())
        .filter(|t| !t.is_empty());
    let (listen, name) = parse_listen(listen_arg)?;
    if !listen.ip().is_loopback() && token.is_none() {
        return Err(crate::exit::Usage(format!(
            "--listen {} serves the panel beyond this PC: give an access token too (--token SECRET or \
             $TRIBO_PANEL_TOKEN), then open http://IP-OF-THIS-PC:{}/?token=SECRET; or keep the default \
             loopback address",
            listen_arg,
            listen.port()
        ))
        .into());
    }
    let store = link.writable_store()?;
    let server = tiny_http::Server::http(listen).map_err(|e| {
        anyhow::anyhow!(
            "cannot serve the panel on {}: {e}; is another panel running? Choose another address with \
             --listen (127.0.0.1:0 picks a free port)",
            listen_arg
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
    let rig = LinkThread {
        link: link.clone(),
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
        .context("starting the panel's link thread")?;
    let page_needs_token = token.is_some();
    let token = token.unwrap_or_else(fresh_token);
    let ctx = Ctx {
        shared,
        cmds: tx,
        safe,
        abort: run_abort.clone(),
        quit: quit.clone(),
        token: token.clone(),
        page_needs_token,
        origin: Origin {
            addr,
            names: name.clone().into_iter().collect(),
        },
        store,
    };
    let shown = match &name {
        Some(n) => format!("{n}:{}", addr.port()),
        None if addr.ip().is_unspecified() => format!("IP-OF-THIS-PC:{}", addr.port()),
        None => addr.to_string(),
    };
    crate::out::text(&format!("front panel on http://{shown}/?token={token}\n"))?;
    if !quiet {
        crate::errln!("open it in a browser; Ctrl-C closes the panel (the rig is made safe)");
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

/// Whether the request carries the access token.
fn authorised(req: &Request, t: &str) -> bool {
    if query(req.url(), "token") == Some(t) || header_value(req, "X-Panel-Token") == Some(t) {
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
    // Only requests addressed to this panel, from its own page: before anything else.
    if let Err(why) = ctx.origin.check(&req) {
        {
            let mut s = lock(&ctx.shared);
            s.refused = (s.refused.0 + 1, Some(why.clone()));
        }
        let _ = req.respond(
            Response::from_string(format!(
                "refused: {why}. The panel answers only to its own address (open the address \
                 `tribo panel` printed)\n"
            ))
            .with_status_code(403),
        );
        return;
    }
    let open = {
        let path = req.url().split('?').next().unwrap_or("/");
        *req.method() == Method::Get
            && (path == "/panel.js" || (path == "/" && !ctx.page_needs_token))
    };
    if !open && !authorised(&req, &ctx.token) {
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
            r = r.with_header(header(
                "Set-Cookie",
                &format!(
                    "tribo_panel={}; Path=/; HttpOnly; SameSite=Strict",
                    ctx.token
                ),
            ));
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
        // From any page, at any time, whatever the link thread is doing.
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
        "release" => {
            let confirmed = args.get("confirm").and_then(Value::as_bool) == Some(true);
            if let (false, Some(why)) = (confirmed, lock(&ctx.shared).settling()) {
                // `tribo run` waits for the plate; a page asks its user first.
                return (
                    409,
                    json!({
                        "ok": false,
                        "confirm": true,
                        "text": format!(
                            "release: {why}; a run released now is not at the temperature set \
                             (`tribo run` would wait). Release anyway?"
                        ),
                    }),
                );
            }
            Cmd::Release
        }
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
                "{name}: no answer from the link thread in 15 s; check the rig line"
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

#[cfg(test)]
mod tests {
    use super::Origin;

    #[test]
    fn a_host_is_answered_to_only_when_it_names_the_panel() {
        let named = Origin {
            addr: "10.0.0.5:7420".parse().unwrap(),
            names: vec!["lab-pc".into()],
        };
        for ok in ["lab-pc:7420", "LAB-PC:7420", "10.0.0.5:7420"] {
            assert!(named.allows(ok), "{ok}");
        }
        for bad in [
            "lab-pc:80",
            "lab-pc",
            "other:7420",
            "localhost:7420",
            "127.0.0.1:7420",
            "[::1]:7420",
            "10.0.0.6:7420",
            ":7420",
            "lab-pc:7420:1",
        ] {
            assert!(!named.allows(bad), "{bad}");
        }
        let any = Origin {
            addr: "0.0.0.0:7420".parse().unwrap(),
            names: vec![],
        };
        assert!(any.allows("192.168.1.9:7420"));
        assert!(!any.allows("lab-pc:7420"), "a name not given with --listen");
        assert!(!any.allows("192.168.1.9:7421"));
        let local = Origin {
            addr: "127.0.0.1:7420".parse().unwrap(),
            names: vec![],
        };
        for ok in [
            "127.0.0.1:7420",
            "localhost:7420",
            "[::1]:7420",
            "127.0.0.2:7420",
        ] {
            assert!(local.allows(ok), "{ok}");
        }
        assert!(!local.allows("attacker.example:7420"));
    }
}
