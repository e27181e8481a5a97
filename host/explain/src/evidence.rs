//! The evidence that an effect shrinks the gap by more than chance: per channel, with the
//! residuals' correlation taken into account.

use super::*;

/// One channel's part of the evidence for an effect.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelEvidence {
    /// `envelope` or `force`.
    pub channel: String,
    /// Residual sum of squares before and after adding the effect.
    pub rss_before: f64,
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
    /// Fraction of the excess misfit (gap² − floor²) the effect removes (1 if there was none).
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
        let floor2 = data.noise_floor().powi(2);
        let excess = before.gap.powi(2) - floor2;
        let excess_removed = if excess > 0.0 {
            (before.gap.powi(2) - after.gap.powi(2)) / excess
        } else {
            1.0
        };
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
