//! The lab catalog's address: a `postgres://` URL without a password, the password from the
//! environment (`PGPASSWORD`) or the password file (`PGPASSFILE`, else `~/.pgpass`, on Windows
//! `%APPDATA%\postgresql\pgpass.conf`), as libpq reads them.
//!
//! A password written in the URL is refused: a command line is seen by every user of the PC (the
//! process list) and kept in shell histories. Whatever is shown of the URL ([`LabUrl::shown`],
//! every error) never holds a password.

use crate::{err, Result};
use std::path::PathBuf;

/// How the connection is protected.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Tls {
    /// Plain TCP (or a Unix socket): no `sslmode`, or `sslmode=disable`.
    Off,
    /// TLS, the server's certificate verified against `root` (a PEM file: `sslrootcert=`) or else
    /// the public web roots; `require` (TLS if the server offers it: `prefer`) or not.
    On {
        /// The CA certificate (`sslrootcert=`), else the public web roots.
        root: Option<PathBuf>,
        /// TLS required (`require`, `verify-ca`, `verify-full`), or only used when offered
        /// (`prefer`).
        required: bool,
    },
}

/// A parsed lab catalog URL with its credentials.
#[derive(Clone)]
pub struct LabUrl {
    shown: String,
    pub(crate) config: postgres::Config,
    pub(crate) tls: Tls,
    /// A password file passed over, and why (others may read it), as libpq passes it over.
    pub(crate) pgpass_ignored: Option<String>,
}

impl std::fmt::Debug for LabUrl {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never the config: it holds the password.
        f.debug_struct("LabUrl")
            .field("url", &self.shown)
            .field("tls", &self.tls)
            .finish()
    }
}

const KEYS: &[&str] = &[
    "sslmode",
    "sslrootcert",
    "connect_timeout",
    "application_name",
    "host",
    "port",
    "user",
    "dbname",
];

/// The URL with any password replaced by `***` (in the user part and in a `password=` parameter):
/// what messages may show of a URL that was refused.
pub fn redact(url: &str) -> String {
    let (head, query) = match url.split_once('?') {
        Some((h, q)) => (h, Some(q)),
        None => (url, None),
    };
    let mut out = match head.split_once("://") {
        Some((scheme, rest)) => {
            let (auth, path) = match rest.find('/') {
                Some(i) => rest.split_at(i),
                None => (rest, ""),
            };
            let auth = match auth.rsplit_once('@') {
                Some((user, host)) => match user.split_once(':') {
                    Some((u, _)) => format!("{u}:***@{host}"),
                    None => auth.to_string(),
                },
                None => auth.to_string(),
            };
            format!("{scheme}://{auth}{path}")
        }
        None => head.to_string(),
    };
    if let Some(q) = query {
        let q: Vec<String> = q
            .split('&')
            .map(|kv| match kv.split_once('=') {
                Some((k, _)) if k.eq_ignore_ascii_case("password") => format!("{k}=***"),
                _ => kv.to_string(),
            })
            .collect();
        out.push('?');
        out.push_str(&q.join("&"));
    }
    out
}

impl LabUrl {
    /// Parses `url`, reading the user and password from the process's environment and password
    /// file.
    pub fn parse(url: &str) -> Result<LabUrl> {
        LabUrl::parse_with(url, &|k| std::env::var(k).ok().filter(|v| !v.is_empty()))
    }

    /// Parses `url` with `env` standing for the environment (`PGUSER`, `PGPASSWORD`, `PGPASSFILE`,
    /// `HOME`, `APPDATA`, `USER`, `USERNAME`).
    pub fn parse_with(url: &str, env: &dyn Fn(&str) -> Option<String>) -> Result<LabUrl> {
        let url = url.trim();
        let shown = redact(url);
        let usage = "write postgres://USER@HOST[:PORT]/DATABASE[?sslmode=require], the password in \
                     PGPASSWORD or ~/.pgpass (or leave --catalog and TRIBO_CATALOG unset for this PC's own catalog)";
        if url.chars().any(|c| c.is_control() || c.is_whitespace()) {
            return Err(crate::usage(format!(
                "the catalog URL {:?} holds a space or a control character: {usage}",
                shown.escape_default().to_string()
            )));
        }
        let Some((scheme, rest)) = url.split_once("://") else {
            return Err(crate::usage(format!(
                "{shown:?} is not a PostgreSQL URL: {usage}"
            )));
        };
        if scheme != "postgres" && scheme != "postgresql" {
            return Err(crate::usage(format!(
                "{shown:?} is not a PostgreSQL URL (scheme {scheme:?}): {usage}"
            )));
        }
        let (head, query) = match rest.split_once('?') {
            Some((h, q)) => (h, q),
            None => (rest, ""),
        };
        let auth = head.split('/').next().unwrap_or("");
        if let Some((user, _)) = auth.rsplit_once('@') {
            if user.contains(':') {
                return Err(crate::usage(format!(
                    "the catalog URL {shown} holds a password: a command line is seen by every user \
                     of the PC and kept in shell histories. Remove it from the URL and put it in \
                     PGPASSWORD or in ~/.pgpass (HOST:PORT:DATABASE:USER:PASSWORD, mode 0600; on \
                     Windows %APPDATA%\\postgresql\\pgpass.conf)"
                )));
            }
        }
        let mut tls_mode = None;
        let mut root = None;
        let mut kept = Vec::new();
        let mut has_timeout = false;
        let mut has_app = false;
        for kv in query.split('&').filter(|s| !s.is_empty()) {
            let (k, v) = kv.split_once('=').unwrap_or((kv, ""));
            match k {
                "password" => {
                    return Err(crate::usage(format!(
                        "the catalog URL {shown} holds a password: remove it and put it in \
                         PGPASSWORD or in ~/.pgpass"
                    )))
                }
                "sslmode" => {
                    if !["disable", "prefer", "require", "verify-ca", "verify-full"].contains(&v) {
                        return Err(crate::usage(format!(
                            "sslmode={v:?} in {shown}: use disable, prefer, require, verify-ca or \
                             verify-full (tribo verifies the server's certificate whenever it uses TLS)"
                        )));
                    }
                    tls_mode = Some(v.to_string());
                }
                "sslrootcert" => root = Some(PathBuf::from(percent_decode(v)?)),
                _ if KEYS.contains(&k) => {
                    has_timeout |= k == "connect_timeout";
                    has_app |= k == "application_name";
                    kept.push(kv.to_string());
                }
                _ => {
                    return Err(crate::usage(format!(
                        "unknown parameter {k:?} in the catalog URL {shown}: tribo takes {}",
                        KEYS.join(", ")
                    )))
                }
            }
        }
        if !has_timeout {
            kept.push("connect_timeout=10".into());
        }
        if !has_app {
            kept.push("application_name=tribo".into());
        }
        let (tls, mode) = match tls_mode.as_deref() {
            None | Some("disable") => (Tls::Off, "disable"),
            Some("prefer") => (
                Tls::On {
                    root,
                    required: false,
                },
                "prefer",
            ),
            Some(_) => (
                Tls::On {
                    root,
                    required: true,
                },
                "require",
            ),
        };
        kept.push(format!("sslmode={mode}"));
        let rebuilt = format!("postgresql://{head}?{}", kept.join("&"));
        let mut config: postgres::Config = rebuilt.parse().map_err(|e| {
            crate::caused_usage(
                format!("the catalog URL {shown} cannot be read: {usage}"),
                e,
            )
        })?;
        if config.get_hosts().is_empty() {
            return Err(crate::usage(format!(
                "the catalog URL {shown} names no server: {usage}"
            )));
        }
        if config.get_user().is_none() {
            let user = env("PGUSER")
                .or_else(|| env("USER"))
                .or_else(|| env("USERNAME"))
                .ok_or_else(|| {
                    err(format!(
                        "the catalog URL {shown} names no user and neither PGUSER nor USER is set: \
                         write postgres://USER@HOST/DATABASE"
                    ))
                })?;
            config.user(&user);
        }
        let mut pgpass_ignored = None;
        let pw = match env("PGPASSWORD") {
            Some(pw) => Some(pw),
            None => match pgpass(&config, env) {
                Ok(pw) => pw,
                Err(why) => {
                    pgpass_ignored = Some(why);
                    None
                }
            },
        };
        if let Some(pw) = pw {
            config.password(pw);
        }
        Ok(LabUrl {
            shown,
            config,
            tls,
            pgpass_ignored,
        })
    }

    /// The URL as given (it holds no password: one is refused).
    pub fn shown(&self) -> &str {
        &self.shown
    }

    /// The role the catalog is reached as.
    pub fn user(&self) -> &str {
        self.config.get_user().unwrap_or("")
    }

    /// Whether a password was found (in `PGPASSWORD` or the password file).
    pub fn has_password(&self) -> bool {
        self.config.get_password().is_some()
    }

    /// The password file that was passed over and why (group or world may read it), if any.
    pub fn pgpass_ignored(&self) -> Option<&str> {
        self.pgpass_ignored.as_deref()
    }

    /// Whether and how the connection uses TLS.
    pub fn tls(&self) -> &Tls {
        &self.tls
    }
}

fn percent_decode(s: &str) -> Result<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = s
                .get(i + 1..i + 3)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| err(format!("bad %-escape in {s:?}")))?;
            out.push(hex);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| err(format!("{s:?} is not UTF-8 once decoded")))
}

/// The password file's line for this server, database and user, as libpq reads it: fields
/// `host:port:database:user:password`, `*` matches anything, `\:` and `\\` escape, `#` comments.
/// On Unix a file that the group or others may read or write is passed over, as libpq does (its
/// passwords are as good as public): the error says so.
fn pgpass(
    config: &postgres::Config,
    env: &dyn Fn(&str) -> Option<String>,
) -> std::result::Result<Option<String>, String> {
    let Some(file) = env("PGPASSFILE").map(PathBuf::from).or_else(|| {
        if cfg!(windows) {
            env("APPDATA").map(|a| PathBuf::from(a).join("postgresql").join("pgpass.conf"))
        } else {
            env("HOME").map(|h| PathBuf::from(h).join(".pgpass"))
        }
    }) else {
        return Ok(None);
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        if let Ok(m) = std::fs::metadata(&file) {
            let mode = m.permissions().mode() & 0o777;
            if mode & 0o077 != 0 {
                return Err(format!(
                    "the password file {} was not read: its group or others may read or change it \
                     (mode {mode:04o}); `chmod 600 {}`, as libpq asks",
                    file.display(),
                    file.display()
                ));
            }
        }
    }
    let Ok(text) = std::fs::read_to_string(file) else {
        return Ok(None);
    };
    Ok(pgpass_found(config, &text))
}

fn pgpass_found(config: &postgres::Config, text: &str) -> Option<String> {
    let host = match config.get_hosts().first()? {
        postgres::config::Host::Tcp(h) => h.clone(),
        #[cfg(unix)]
        postgres::config::Host::Unix(_) => "localhost".into(),
    };
    let port = config
        .get_ports()
        .first()
        .copied()
        .unwrap_or(5432)
        .to_string();
    let user = config.get_user().unwrap_or("").to_string();
    let db = config.get_dbname().unwrap_or(&user).to_string();
    pgpass_lookup(text, [&host, &port, &db, &user])
}

/// The password of the first line of a password file matching `want` (host, port, database,
/// user).
pub fn pgpass_lookup(text: &str, want: [&str; 4]) -> Option<String> {
    for line in text.lines() {
        if line.trim_start().starts_with('#') || line.trim().is_empty() {
            continue;
        }
        let mut fields = vec![String::new()];
        let mut chars = line.chars();
        while let Some(c) = chars.next() {
            match c {
                '\\' => {
                    if let Some(n) = chars.next() {
                        fields.last_mut()?.push(n);
                    }
                }
                ':' if fields.len() < 5 => fields.push(String::new()),
                _ => fields.last_mut()?.push(c),
            }
        }
        if fields.len() != 5 {
            continue;
        }
        if fields[..4]
            .iter()
            .zip(want)
            .all(|(f, w)| f == "*" || f == w)
        {
            return Some(fields[4].clone());
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(k: &str) -> Option<String> {
        match k {
            "USER" => Some("lab".into()),
            _ => None,
        }
    }

    #[test]
    fn a_password_in_the_url_is_refused_and_never_shown() {
        for url in [
            "postgres://tribo:s3cret@db.lab/tribo",
            "postgresql://tribo:s3cret@db.lab:5433/tribo?sslmode=require",
            "postgres://tribo@db.lab/tribo?password=s3cret",
        ] {
            let e = LabUrl::parse_with(url, &env).unwrap_err();
            let text = crate::chain(&e);
            assert!(text.contains("PGPASSWORD"), "{text}");
            assert!(!text.contains("s3cret"), "{text}");
        }
        assert_eq!(
            redact("postgres://u:p%40ss@h/db?x=1&password=zz"),
            "postgres://u:***@h/db?x=1&password=***"
        );
    }

    #[test]
    fn malformed_and_hostile_urls_are_refused_with_what_to_write() {
        for (url, says) in [
            ("db.lab/tribo", "not a PostgreSQL URL"),
            ("mysql://db.lab/tribo", "scheme"),
            ("postgres://db.lab:99999/tribo", "cannot be read"),
            (
                "postgres://db.lab/tribo?options=-c%20log_statement%3Dall",
                "unknown parameter",
            ),
            ("postgres://db.lab/tribo\nDROP TABLE x", "control character"),
            ("postgres://db.lab/tribo?sslmode=allow-anything", "sslmode"),
            ("postgres:///tribo", "names no server"),
            ("postgres://db.lab/tribo?sslrootcert=%zz", "escape"),
        ] {
            let e = LabUrl::parse_with(url, &env).unwrap_err();
            let text = crate::chain(&e);
            assert!(text.contains(says), "{url}: {text}");
        }
    }

    #[test]
    fn user_password_and_tls_come_from_the_url_and_the_environment() {
        let u = LabUrl::parse_with("postgres://db.lab/tribo", &env).unwrap();
        assert_eq!(u.user(), "lab");
        assert!(!u.has_password());
        assert_eq!(u.tls(), &Tls::Off);
        let dir = tempfile::tempdir().unwrap();
        let pass = dir.path().join("pgpass");
        std::fs::write(
            &pass,
            "# lab\nother:5432:*:*:nope\ndb.lab:5432:tribo:writer:pa\\:ss\n*:*:*:*:fallback\n",
        )
        .unwrap();
        let p = pass.to_string_lossy().into_owned();
        let env2 = move |k: &str| match k {
            "PGPASSFILE" => Some(p.clone()),
            _ => None,
        };
        // Readable by the group: passed over, and the reason kept for the error to say.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&pass, std::fs::Permissions::from_mode(0o640)).unwrap();
            let u = LabUrl::parse_with("postgres://writer@db.lab/tribo", &env2).unwrap();
            assert!(!u.has_password());
            let why = u.pgpass_ignored().expect("the reason");
            assert!(why.contains("0640") && why.contains("chmod 600"), "{why}");
            std::fs::set_permissions(&pass, std::fs::Permissions::from_mode(0o600)).unwrap();
        }
        let u = LabUrl::parse_with(
            "postgres://writer@db.lab/tribo?sslmode=verify-full&sslrootcert=%2Fetc%2Flab.pem",
            &env2,
        )
        .unwrap();
        assert_eq!(u.config.get_password(), Some(&b"pa:ss"[..]));
        assert_eq!(
            u.tls(),
            &Tls::On {
                root: Some("/etc/lab.pem".into()),
                required: true
            }
        );
        assert!(!format!("{u:?}").contains("pa:ss"));
        let u = LabUrl::parse_with("postgres://reader@db.lab:6000/tribo", &env2).unwrap();
        assert_eq!(u.config.get_password(), Some(&b"fallback"[..]));
        let env3 = |k: &str| (k == "PGPASSWORD").then(|| "fromenv".to_string());
        let u = LabUrl::parse_with("postgres://x@db.lab/tribo", &env3).unwrap();
        assert_eq!(u.config.get_password(), Some(&b"fromenv"[..]));
    }
}
