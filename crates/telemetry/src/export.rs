//! The scrape: parts of the daemon that implement [`Collect`] write their
//! current values through a [`Scrape`] into `prometheus-client`'s encoder
//! for the Prometheus text format (version 0.0.4), which `promtool check
//! metrics` and every Prometheus server read.

use crate::histogram::{upper_edge_seconds, BUCKETS};
use crate::Histogram;
use prometheus_client::encoding::{DescriptorEncoder, NoLabelSet};
use prometheus_client::metrics::MetricType;
use prometheus_client::registry::Registry;
use std::fmt;
use std::sync::Arc;

/// The HTTP `Content-Type` of [`Exposition::render`]'s text.
pub const CONTENT_TYPE: &str = prometheus_client::encoding::prometheus_text::CONTENT_TYPE;

/// Fine buckets merged into one exported bucket: the exposition carries
/// two edges per octave (the quantiles printed by the daemon use all eight).
const EXPORT_STRIDE: usize = 4;

/// Something with metrics: writes its current values on every scrape.
pub trait Collect: Send + Sync + 'static {
    /// Writes every metric, each with its help text.
    fn collect(&self, out: &mut Scrape<'_>) -> fmt::Result;
}

/// Where a [`Collect`] writes its metrics during one scrape.
pub struct Scrape<'a> {
    encoder: DescriptorEncoder<'a>,
}

impl fmt::Debug for Scrape<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Scrape").finish_non_exhaustive()
    }
}

/// Whether `name` follows the scheme: `photopose_` prefix, lower snake case.
fn well_named(name: &str) -> bool {
    name.starts_with("photopose_")
        && name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_')
        && !name.contains("__")
        && !name.ends_with('_')
}

impl Scrape<'_> {
    /// A counter named `…_total`.
    pub fn counter(&mut self, name: &str, help: &str, value: u64) -> fmt::Result {
        debug_assert!(well_named(name) && name.ends_with("_total"), "{name}");
        // The encoder appends `_total` to counters itself.
        let base = name.strip_suffix("_total").unwrap_or(name);
        let mut m = self
            .encoder
            .encode_descriptor(base, help, None, MetricType::Counter)?;
        m.encode_counter::<NoLabelSet, _, u64>(&value, None)
    }

    /// A gauge.
    pub fn gauge(&mut self, name: &str, help: &str, value: f64) -> fmt::Result {
        debug_assert!(well_named(name) && !name.ends_with("_total"), "{name}");
        let mut m = self
            .encoder
            .encode_descriptor(name, help, None, MetricType::Gauge)?;
        m.encode_gauge(&value)
    }

    /// A gauge with one series per label value (`label="value"`): e.g. a
    /// state as one series per state, 1 for the current one.
    pub fn gauge_family(
        &mut self,
        name: &str,
        help: &str,
        label: &str,
        series: &[(&str, f64)],
    ) -> fmt::Result {
        debug_assert!(well_named(name) && !name.ends_with("_total"), "{name}");
        let mut m = self
            .encoder
            .encode_descriptor(name, help, None, MetricType::Gauge)?;
        for (value, v) in series {
            let labels = [(label, *value)];
            m.encode_family(&labels)?.encode_gauge(v)?;
        }
        Ok(())
    }

    /// A counter with one series per label value.
    pub fn counter_family(
        &mut self,
        name: &str,
        help: &str,
        label: &str,
        series: &[(&str, u64)],
    ) -> fmt::Result {
        debug_assert!(well_named(name) && name.ends_with("_total"), "{name}");
        let base = name.strip_suffix("_total").unwrap_or(name);
        let mut m = self
            .encoder
            .encode_descriptor(base, help, None, MetricType::Counter)?;
        for (value, v) in series {
            let labels = [(label, *value)];
            m.encode_family(&labels)?
                .encode_counter::<NoLabelSet, _, u64>(v, None)?;
        }
        Ok(())
    }

    /// A histogram of durations named `…_seconds` (`_bucket`, `_sum`,
    /// `_count`), two bucket edges per octave.
    pub fn histogram(&mut self, name: &str, help: &str, h: &Histogram) -> fmt::Result {
        debug_assert!(well_named(name) && name.ends_with("_seconds"), "{name}");
        let counts = h.counts();
        let count: u64 = counts.iter().sum();
        // Exported edges: the first and every fourth fine edge after it
        // (1 µs · 2^(j/2)); the overflow bucket goes into the encoder's
        // own `+Inf`.
        let last = BUCKETS - 2;
        let mut buckets: Vec<(f64, u64)> = Vec::with_capacity(last / EXPORT_STRIDE + 1);
        buckets.push((upper_edge_seconds(0), counts[0]));
        for top in (EXPORT_STRIDE..=last).step_by(EXPORT_STRIDE) {
            let n = counts[top + 1 - EXPORT_STRIDE..=top].iter().sum();
            buckets.push((upper_edge_seconds(top), n));
        }
        let mut m = self
            .encoder
            .encode_descriptor(name, help, None, MetricType::Histogram)?;
        m.encode_histogram::<NoLabelSet>(h.sum_seconds(), count, &buckets, None)
    }

    /// An info metric named `…_info`: value 1, the facts in its labels.
    pub fn info(&mut self, name: &str, help: &str, labels: &[(&str, &str)]) -> fmt::Result {
        debug_assert!(well_named(name) && name.ends_with("_info"), "{name}");
        let base = name.strip_suffix("_info").unwrap_or(name);
        let mut m = self
            .encoder
            .encode_descriptor(base, help, None, MetricType::Info)?;
        m.encode_info(&labels)
    }
}

/// Adapts a [`Collect`] to `prometheus-client`'s collector.
struct Adapter(Arc<dyn Collect>);

impl fmt::Debug for Adapter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Adapter")
    }
}

impl prometheus_client::collector::Collector for Adapter {
    fn encode(&self, encoder: DescriptorEncoder) -> fmt::Result {
        self.0.collect(&mut Scrape { encoder })
    }
}

/// Every metric of the daemon: the collectors, in the order registered.
#[derive(Debug, Default)]
pub struct Exposition {
    registry: Registry,
}

impl Exposition {
    /// An exposition without collectors.
    pub fn new() -> Exposition {
        Exposition::default()
    }

    /// Adds a collector.
    pub fn register(&mut self, c: Arc<dyn Collect>) {
        self.registry.register_collector(Box::new(Adapter(c)));
    }

    /// The current values in the Prometheus text format.
    pub fn render(&self) -> String {
        let mut s = String::with_capacity(8192);
        // Writing into a String cannot fail; a collector's error would
        // leave a partial text, which is still returned.
        let _ = prometheus_client::encoding::prometheus_text::encode(&mut s, &self.registry);
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Counter, Gauge};

    #[derive(Default)]
    struct Sample {
        cycles: Counter,
        level: Gauge,
        latency: Histogram,
    }

    impl Collect for Sample {
        fn collect(&self, out: &mut Scrape<'_>) -> fmt::Result {
            out.counter("photopose_test_cycles_total", "Cycles.", self.cycles.get())?;
            out.gauge("photopose_test_level", "A level.", self.level.get())?;
            out.gauge_family(
                "photopose_test_state",
                "The state, 1 for the current one.",
                "state",
                &[("on", 1.0), ("off", 0.0)],
            )?;
            out.histogram(
                "photopose_test_latency_seconds",
                "A latency.",
                &self.latency,
            )?;
            out.info(
                "photopose_test_build_info",
                "The build.",
                &[("version", "1.2.3")],
            )
        }
    }

    #[test]
    fn renders_help_type_and_histogram_series() {
        let s = Arc::new(Sample::default());
        s.cycles.add(7);
        s.level.set(2.5);
        s.latency.record_ns(3_000_000);
        s.latency.record_ns(200_000_000_000);
        let mut e = Exposition::new();
        e.register(s.clone());
        let text = e.render();
        for line in [
            "# HELP photopose_test_cycles_total Cycles.",
            "# TYPE photopose_test_cycles_total counter",
            "photopose_test_cycles_total 7",
            "photopose_test_level 2.5",
            "photopose_test_state{state=\"on\"} 1.0",
            "# TYPE photopose_test_latency_seconds histogram",
            "photopose_test_latency_seconds_bucket{le=\"+Inf\"} 2",
            "photopose_test_latency_seconds_count 2",
            "photopose_test_build_info{version=\"1.2.3\"} 1",
        ] {
            assert!(text.lines().any(|l| l == line), "{line} missing:\n{text}");
        }
        // Cumulative buckets: 0 up to edges below 3 ms, 1 from the first
        // edge above it (2^(j/2) µs: 2.896 ms, then 4.096 ms).
        let buckets: Vec<(f64, u64)> = text
            .lines()
            .filter_map(|l| l.strip_prefix("photopose_test_latency_seconds_bucket{le=\""))
            .filter(|l| !l.starts_with('+'))
            .map(|l| {
                let (le, n) = l.split_once("\"} ").unwrap();
                (le.parse().unwrap(), n.parse().unwrap())
            })
            .collect();
        assert_eq!(buckets.len(), 55, "{text}");
        for (le, n) in buckets {
            assert_eq!(n, u64::from(le >= 3e-3), "le {le}:\n{text}");
        }
        assert!(text.contains("photopose_test_latency_seconds_sum 200.003"));
    }
}
