//! The evidence that an effect shrinks the gap by more than chance: per channel, with the
//! residuals' correlation taken into account.

use super::*;

/// One channel's part of the evidence for an effect.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelEvidence {
    /// `envelope` or `force`.
    pub channel: String,
    /// Residual sum of squares before adding the effect.
    pub rss_before: f64,
    /// Residual sum of squares after adding it.
    pub rss_after: f64,
    /// Compared points.
    pub n: usize,
    /// Effectively independent residuals of the noise model (from the model without the effect).
    pub n_eff: f64,
    /// Residual variance of the noise model (never below the channel's noise floor²).
    pub noise_var: f64,
    /// This channel's evidence.
    pub evidence: f64,
}

/// How strongly adding an effect is supported.
#[derive(Debug, Clone, Serialize)]
pub struct Evidence {
    /// Sum over the channels: χ² with `k` degrees of freedom if the effect is absent.
    pub value: f64,
    /// What it must exceed ([`ExplainOptions::threshold`]).
    pub threshold: f64,
    /// Parameters the effect adds.
    pub k: usize,
    /// Fraction of the excess misfit the effect removes (1 if there was none): the evidence over
    /// `Σ_c n_eff_c max(g(r_c) − g(1 + 2 u_c), 0)` of the model without it, in the same
    /// likelihood's units ([`crate::model::NoiseModel`]); `u_c = √(2 / n_eff_c + ε_c²)` is how well
    /// a right model's mean square residual and the floor² (to ±`ε_c`,
    /// [`Prepared::floor_rel_se`]) are known, so a misfit within 2 of them is not an excess.
    pub excess_removed: f64,
    /// Per channel.
    pub channels: Vec<ChannelEvidence>,
}

impl Evidence {
    /// Evidence of `after` (the current model plus one effect) against `before`, both fitted
    /// under the same noise model ([`Prepared::noise`], [`crate::model::NoiseModel`]): twice the
    /// log-likelihood ratio of the profile likelihood, `Σ_c n_eff_c (g(r_c(before)) −
    /// g(r_c(after)))` with `r_c = RSS_c / (n_c floor_c²)` and `g(r) = r` up to the floor, `1 + ln r`
    /// above, whose gradient is the weighted least squares the fits minimise; and the share of
    /// `before`'s excess misfit (its deviance above what noise at each channel's floor leaves,
    /// `Σ_c n_eff_c max(g(r_c) − g(1 + 2 u_c), 0)`, with `u_c` how well a right model's mean
    /// square and the floor² are known) that the same sum is.
    pub fn of(
        data: &Prepared,
        before: &FittedModel,
        after: &FittedModel,
        opts: &ExplainOptions,
    ) -> Evidence {
        let k = after.p.len().saturating_sub(before.p.len()).max(1);
        let mut channels = Vec::new();
        let mut excess = 0.0;
        for (name, rb, ra, floor) in [
            (
                "envelope",
                &before.env_resid,
                &after.env_resid,
                data.env_floor(),
            ),
            (
                "force",
                &before.force_resid,
                &after.force_resid,
                data.force_floor(),
            ),
        ] {
            if ra.is_empty() {
                continue;
            }
            let n = ra.len();
            let ss = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
            let (rss_b, rss_a) = (ss(rb), ss(ra));
            // The noise model's variance and count (the floor with independent residuals when
            // none is set), reported as they enter `w = n_eff / (n s²)`.
            let (noise_var, n_eff) = match (&data.noise, name) {
                (Some(m), "envelope") => (m.env_var, m.env_n_eff.min(n as f64)),
                (Some(m), _) => (m.force_var, m.force_n_eff.min(n as f64)),
                (None, _) => (floor * floor, n as f64),
            };
            // The profile likelihood's deviance of the channel at `r = RSS / (n floor²)`, its
            // variance fitted (never below the floor²): `n_eff · g(r)`, g(r) = r up to the floor,
            // 1 + ln r above ([`crate::model::NoiseModel`]).
            let g = |r: f64| if r <= 1.0 { r } else { 1.0 + r.ln() };
            let unit = n as f64 * floor * floor;
            let evidence = n_eff * (g(rss_b / unit) - g(rss_a / unit));
            // The misfit above the noise counts where it stands out of what noise at the floor
            // leaves, as well as the two are known: the floor² read from the record to
            // ±`floor_rel_se`, the mean square residual of a right model to ±√(2 / n_eff), at 2σ
            // (grid #87: the force channel at 1.0049 × its floor² over 93 k points, within the
            // floor's own ±0.7 %, made 452 units of "excess" no effect could remove).
            let rel =
                2.0 * (2.0 / n_eff.max(1.0) + data.floor_rel_se(name == "force").powi(2)).sqrt();
            excess += n_eff * (g(rss_b / unit) - g(1.0 + rel)).max(0.0);
            channels.push(ChannelEvidence {
                channel: name.into(),
                rss_before: rss_b,
                rss_after: rss_a,
                n,
                n_eff,
                noise_var,
                evidence,
            });
        }
        // The release instant's prior (a record held before its release): its `−2 ln L` term.
        let value: f64 = channels.iter().map(|c| c.evidence).sum::<f64>()
            + data.release_chi2(&before.spec, &before.p)
            - data.release_chi2(&after.spec, &after.p);
        let excess_removed = if excess > 0.0 { value / excess } else { 1.0 };
        Evidence {
            value,
            threshold: opts.threshold(k),
            k,
            excess_removed,
            channels,
        }
    }

    /// Whether the effect qualifies: enough evidence and a material share of the excess misfit.
    pub fn significant(&self, opts: &ExplainOptions) -> bool {
        self.value >= self.threshold && self.excess_removed >= opts.min_excess_reduction
    }
}
