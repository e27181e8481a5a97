//! Writes a campaign report of made-up points (2 temperatures × 3 loads × 3 repetitions) into the
//! directory given (default `target/simulated-campaign`), to look at the campaign figures.
use std::path::PathBuf;
use tribo_report::{write_campaign_report, CampaignInputs, CampaignPoint};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "target/simulated-campaign".into()),
    );
    let mut pts = Vec::new();
    for (ti, t) in [25.0, 60.0].into_iter().enumerate() {
        for (li, n) in [0.1, 0.3, 0.5].into_iter().enumerate() {
            for r in 0..3 {
                pts.push(CampaignPoint {
                    run: format!("T{t}-N{n}-{r}"),
                    load_n: n,
                    temp_c: Some(t),
                    temp_setpoint_c: Some(t),
                    mu0: Some(0.010 + 0.003 * ti as f64 + 0.0004 * r as f64 + 0.001 * li as f64),
                    mu1: Some(0.004 - 0.0015 * ti as f64 + 0.0001 * r as f64),
                    mu0_se: None,
                    mu1_se: None,
                    cycles: Some(60.0 - 15.0 * li as f64 - 8.0 * ti as f64 + r as f64),
                });
            }
        }
    }
    let inputs = CampaignInputs {
        title: "Made-up campaign".into(),
        png: true,
    };
    let files = write_campaign_report(&pts, &inputs, &out)?;
    println!("{}", files.html.display());
    Ok(())
}
