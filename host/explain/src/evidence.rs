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
    /// Effectively independent residuals after adding the effect.
    pub n_eff: f64,
    /// Residual variance used as the noise level (never below the channel's noise floor²).
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
    /// Fraction of the excess misfit the effect removes (1 if there was none): `Σ_c (gap_c² −
    /// floor_c²)` over the channels, each in units of its own noise floor².
    pub excess_removed: f64,
    /// Per channel.
    pub channels: Vec<ChannelEvidence>,
}

impl Evidence {
    /// Evidence of `after` (the current model plus one effect) against `before`.
    pub fn of(
        data: &Prepared,
        before: &FittedModel,
        after: &FittedModel,
        opts: &ExplainOptions,
    ) -> Evidence {
        let k = after.p.len().saturating_sub(before.p.len()).max(1);
        let mut channels = Vec::new();
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
            let n_eff = effective_count(ra);
            let noise_var = (rss_a / n as f64).max(floor * floor);
            let evidence = (rss_b - rss_a) / (noise_var * n as f64 / n_eff);
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
        // The misfit above the noise, each channel in units of its own noise floor (a noisy
        // vibrometer must not hide what the force channel shows, nor the reverse).
        let mut excess = 0.0;
        let mut removed = 0.0;
        for (gb, ga, floor) in [
            (before.gap_envelope, after.gap_envelope, data.env_floor()),
            (
                before.gap_force.unwrap_or(0.0),
                after.gap_force.unwrap_or(0.0),
                data.force_floor(),
            ),
        ] {
            if floor > 0.0 {
                excess += ((gb * gb - floor * floor) / (floor * floor)).max(0.0);
                removed += (gb * gb - ga * ga) / (floor * floor);
            }
        }
        let excess_removed = if excess > 0.0 { removed / excess } else { 1.0 };
        Evidence {
            value: channels.iter().map(|c| c.evidence).sum(),
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
