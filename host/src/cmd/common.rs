//! What several commands share of their command lines: `--catalog`'s help and the period
//! (`--since`/`--until`). Shared logic is in the library's modules, not here.

use tribo_store::Filter;

/// The help of `--catalog` in `runs`, `table`, `report` and `pull`.
pub const CATALOG_HELP: &str = "The lab catalog to read instead of this PC's own: a PostgreSQL URL, postgres://USER@HOST[:PORT]/DATABASE[?sslmode=verify-full&sslrootcert=CA.pem] (default: $TRIBO_CATALOG, else the store's SQLite catalog). No password in it: it comes from PGPASSWORD or ~/.pgpass";

/// `--since`/`--until`: the days a command's runs were taken in (`tribo runs`, `table`, `report
/// CAMPAIGN`), on the local and the lab catalog alike.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct Period {
    /// Runs taken on or after this day (UTC), e.g. `--since 2026-01-01` for this year's.
    #[arg(long, value_name = "YYYY-MM-DD", value_parser = day)]
    pub since: Option<String>,
    /// Runs taken on or before this day (UTC).
    #[arg(long, value_name = "YYYY-MM-DD", value_parser = day)]
    pub until: Option<String>,
}

impl Period {
    /// A period that ends before it begins is a usage error (status 2).
    pub fn check(&self) -> anyhow::Result<()> {
        if let (Some(a), Some(b)) = (&self.since, &self.until) {
            if a > b {
                return Err(crate::exit::Usage(format!(
                    "--since {a} is after --until {b}: no run can be in between"
                ))
                .into());
            }
        }
        Ok(())
    }

    /// `f` restricted to the period.
    pub fn apply(&self, f: Filter) -> Filter {
        Filter {
            since: self.since.clone(),
            until: self.until.clone(),
            ..f
        }
    }
}

fn day(s: &str) -> Result<String, String> {
    if tribo_store::catalog::is_day(s) {
        Ok(s.to_string())
    } else {
        Err(format!(
            "{s:?} is not a day: write it YYYY-MM-DD, e.g. 2026-01-01"
        ))
    }
}
