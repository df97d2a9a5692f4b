//! Property tests of the two parsers that read foreign input — the
//! controller's `<Rob>` datagrams and its `RSI_EthernetConfig.xml` — and the
//! controller file's linear cost on a 10 MB input: no panics on any bytes,
//! errors that say what and where, valid documents read back exactly.

use photopose_rsi::codec::{parse_rob, CodecError, POSE_ATTRS};
use photopose_rsi::config::ConfigError;
use photopose_rsi::ethernet_config::{EthernetConfig, EthernetConfigError};
use photopose_rsi::RsiConfig;
use proptest::prelude::*;
use proptest::test_runner::RngAlgorithm;

/// The byte offset an error names, if it names one.
fn offset(e: &CodecError) -> Option<usize> {
    match *e {
        CodecError::Truncated { at, .. }
        | CodecError::Syntax { at, .. }
        | CodecError::NotRob { at }
        | CodecError::BadNumber { at, .. }
        | CodecError::OutOfRange { at, .. }
        | CodecError::Duplicate { at, .. }
        | CodecError::MissingAttribute { at, .. }
        | CodecError::BadIpoc { at } => Some(at),
        _ => None,
    }
}

fn check_error(e: &CodecError, len: usize) {
    assert!(!e.to_string().is_empty());
    assert!(!e.kind().is_empty());
    if let Some(at) = offset(e) {
        assert!(at <= len, "{e} beyond {len} bytes");
    }
}

/// A pose printed with `decimals` decimals, attributes in `order`.
fn pose_text(name: &str, p: &[f64; 6], order: &[usize], decimals: usize, sep: &str) -> String {
    let mut s = format!("<{name}");
    for &i in order {
        s.push_str(&format!("{sep}{}=\"{:.*}\"", POSE_ATTRS[i], decimals, p[i]));
    }
    s.push_str("/>");
    s
}

fn round(v: f64, d: usize) -> f64 {
    format!("{v:.d$}").parse().unwrap()
}

prop_compose! {
    fn pose()(t in proptest::array::uniform3(-3000.0f64..3000.0),
              r in proptest::array::uniform3(-180.0f64..180.0)) -> [f64; 6] {
        [t[0], t[1], t[2], r[0], r[1], r[2]]
    }
}

fn name() -> impl Strategy<Value = String> {
    "[A-Za-z_][A-Za-z0-9_]{0,10}"
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 1000,
        rng_algorithm: RngAlgorithm::ChaCha,
        ..ProptestConfig::default()
    })]

    #[test]
    fn rob_random_bytes_give_errors_that_say_where(bytes in proptest::collection::vec(any::<u8>(), 0..800)) {
        if let Err(e) = parse_rob(&bytes) {
            check_error(&e, bytes.len());
        }
    }

    #[test]
    fn rob_valid_datagrams_read_back_exactly(
        rist in pose(), rsol in pose(),
        order_a in Just([0usize, 1, 2, 3, 4, 5]).prop_shuffle(),
        order_b in Just([0usize, 1, 2, 3, 4, 5]).prop_shuffle(),
        decimals in 0usize..9,
        delay in 0u64..100_000,
        ipoc in any::<u64>(),
        zeros in 0usize..3,
        layout in Just([0usize, 1, 2, 3, 4]).prop_shuffle(),
        upper_type in any::<bool>(),
        sep in prop_oneof![Just(" "), Just("  "), Just("\n\t")],
        with_rist in any::<bool>(),
        with_delay in any::<bool>(),
    ) {
        // At most 20 digits in all.
        let zeros = zeros.min(20 - ipoc.to_string().len());
        let mut parts = vec![String::new(); 5];
        if with_rist {
            parts[0] = pose_text("RIst", &rist, &order_a, decimals, sep);
        }
        parts[1] = pose_text("RSol", &rsol, &order_b, decimals, sep);
        if with_delay {
            parts[2] = format!("<Delay D=\"{delay}\"/>");
        }
        parts[3] = "<Tech C11=\"1.5\" T21=\"x\"/><AIPos A1=\"1\"/><DiL>7</DiL>".into();
        parts[4] = format!("<IPOC>{}{ipoc}</IPOC>", "0".repeat(zeros));
        let mut doc = format!("<Rob {}=\"KUKA\">", if upper_type { "TYPE" } else { "Type" });
        for &k in &layout {
            doc.push_str(&parts[k]);
            doc.push_str(sep);
        }
        doc.push_str("</Rob>");
        let f = parse_rob(doc.as_bytes()).map_err(|e| TestCaseError::fail(format!("{e}: {doc}")))?;
        prop_assert_eq!(f.ipoc.value(), ipoc);
        prop_assert_eq!(f.ipoc.as_str(), format!("{}{ipoc}", "0".repeat(zeros)));
        prop_assert_eq!(f.rsol, Some(rsol.map(|v| round(v, decimals))));
        prop_assert_eq!(f.rist, with_rist.then(|| rist.map(|v| round(v, decimals))));
        prop_assert_eq!(f.delay, with_delay.then_some(delay));
    }

    #[test]
    fn rob_mutations_are_errors_or_plausible(
        rsol in pose(), ipoc in any::<u64>(),
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
        cut in any::<prop::sample::Index>(),
    ) {
        let doc = format!(
            "<Rob Type=\"KUKA\">{}<Delay D=\"3\"/><IPOC>{ipoc}</IPOC></Rob>",
            pose_text("RSol", &rsol, &[0, 1, 2, 3, 4, 5], 4, " ")
        );
        let mut d = doc.into_bytes();
        for (i, b) in &edits {
            let at = i.index(d.len());
            d[at] = *b;
        }
        let keep = cut.index(d.len() + 1).max(d.len() / 2);
        d.truncate(keep);
        match parse_rob(&d) {
            Err(e) => check_error(&e, d.len()),
            Ok(f) => {
                // Whatever survived is finite, inside the plausible range,
                // and the IPOC is digits that stand in the datagram.
                for p in f.rsol.iter().chain(f.rist.iter()) {
                    prop_assert!(p.iter().all(|v| v.is_finite()));
                    prop_assert!(p[..3].iter().all(|v| v.abs() <= 1e5));
                    prop_assert!(p[3..].iter().all(|v| v.abs() <= 360.0));
                }
                let digits = f.ipoc.as_str();
                let text = String::from_utf8_lossy(&d);
                let found = text.contains(digits);
                prop_assert!(found, "IPOC {} not in {}", digits, text);
                prop_assert!(f.delay.is_none_or(|v| v <= u64::from(u32::MAX)));
            }
        }
    }
}

/// A controller file: the keys, SEND tags, RECEIVE tags `(element,
/// attribute, holdon)`; returns the text and the line of each RECEIVE tag.
fn controller_file(
    port: u16,
    sentype: &str,
    send: &[String],
    receive: &[(String, Option<String>, Option<bool>)],
    comments: bool,
) -> (String, Vec<usize>) {
    let mut t = String::from("<?xml version=\"1.0\"?>\n<ROOT>\n  <CONFIG>\n");
    t.push_str("    <IP_NUMBER>192.168.1.20</IP_NUMBER>\n");
    t.push_str(&format!("    <PORT>{port}</PORT>\n"));
    t.push_str(&format!("    <SENTYPE>{sentype}</SENTYPE>\n"));
    t.push_str("    <ONLYSEND>FALSE</ONLYSEND>\n  </CONFIG>\n  <SEND>\n    <ELEMENTS>\n");
    for s in send {
        t.push_str(&format!(
            "      <ELEMENT TAG=\"{s}\" TYPE=\"DOUBLE\" INDX=\"INTERNAL\"/>\n"
        ));
    }
    t.push_str("    </ELEMENTS>\n  </SEND>\n  <RECEIVE>\n    <ELEMENTS>\n");
    let mut lines = Vec::new();
    for (k, (e, a, h)) in receive.iter().enumerate() {
        if comments && k % 3 == 0 {
            t.push_str("      <!-- <ELEMENT TAG=\"Not.Me\"/>\n      -->\n");
        }
        lines.push(t.matches('\n').count() + 1);
        let tag = match a {
            Some(a) => format!("{e}.{a}"),
            None => e.clone(),
        };
        let holdon = match h {
            Some(true) => " HOLDON=\"1\"",
            Some(false) => " HOLDON=\"0\"",
            None => "",
        };
        t.push_str(&format!(
            "      <ELEMENT TAG=\"{tag}\" TYPE=\"DOUBLE\" INDX=\"{}\"{holdon}/>\n",
            k + 1
        ));
    }
    t.push_str("    </ELEMENTS>\n  </RECEIVE>\n</ROOT>\n");
    (t, lines)
}

fn receive_list() -> impl Strategy<Value = Vec<(String, Option<String>, Option<bool>)>> {
    let tag = (
        name(),
        proptest::option::of(name()),
        proptest::option::of(any::<bool>()),
    );
    (
        proptest::collection::vec(tag, 0..8),
        Just([0usize, 1, 2, 3, 4, 5]).prop_shuffle(),
        proptest::option::of(any::<bool>()),
        any::<prop::sample::Index>(),
    )
        .prop_map(|(mut extra, order, holdon, at)| {
            let at = at.index(extra.len() + 1);
            let korr: Vec<_> = order
                .iter()
                .map(|&i| ("RKorr".to_string(), Some(POSE_ATTRS[i].to_string()), holdon))
                .collect();
            extra.splice(at..at, korr);
            extra
        })
}

fn check_config_error(e: &EthernetConfigError, lines: usize) {
    assert!(!e.to_string().is_empty());
    match e {
        EthernetConfigError::Xml { line, .. }
        | EthernetConfigError::BadValue { line, .. }
        | EthernetConfigError::NotAName { line, .. } => {
            assert!((1..=lines + 1).contains(line), "{e} of {lines} lines")
        }
        _ => {}
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 500,
        rng_algorithm: RngAlgorithm::ChaCha,
        ..ProptestConfig::default()
    })]

    #[test]
    fn controller_files_read_back_exactly(
        port in 1u16..,
        sentype in name(),
        send in proptest::collection::vec("DEF_[A-Za-z]{1,8}", 0..5),
        receive in receive_list(),
        comments in any::<bool>(),
    ) {
        let (text, lines) = controller_file(port, &sentype, &send, &receive, comments);
        let c = EthernetConfig::parse(&text).map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
        prop_assert_eq!(c.port, port);
        prop_assert_eq!(&c.sentype, &sentype);
        prop_assert_eq!(&c.send, &send);
        prop_assert_eq!(c.receive.len(), receive.len());
        for ((r, want), line) in c.receive.iter().zip(&receive).zip(&lines) {
            prop_assert_eq!(&r.element, &want.0);
            prop_assert_eq!(&r.attribute, &want.1);
            prop_assert_eq!(r.holdon, want.2);
            prop_assert_eq!(r.line, *line);
        }
        let f = c.sen_format(4).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(&f.sentype, &sentype);
        prop_assert_eq!(f.correction_element.as_str(), "RKorr");
    }

    #[test]
    fn controller_file_mutations_are_errors_that_say_where(
        receive in receive_list(),
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        cut in any::<prop::sample::Index>(),
    ) {
        let (text, _) = controller_file(49152, "ImFree", &["DEF_RSol".to_string()], &receive, true);
        let mut d = text.into_bytes();
        for (i, b) in &edits {
            let at = i.index(d.len());
            d[at] = *b;
        }
        d.truncate(cut.index(d.len() + 1).max(d.len() / 2));
        let text = String::from_utf8_lossy(&d);
        let lines = text.matches('\n').count() + 1;
        match EthernetConfig::parse(&text) {
            Err(e) => check_config_error(&e, lines),
            Ok(c) => {
                // What is read is usable: the names are XML names.
                prop_assert!(photopose_rsi::xml::is_xml_name(c.sentype.as_bytes()));
                for r in &c.receive {
                    prop_assert!(photopose_rsi::xml::is_xml_name(r.element.as_bytes()));
                }
            }
        }
    }

    #[test]
    fn controller_file_random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..800)) {
        let text = String::from_utf8_lossy(&bytes);
        if let Err(e) = EthernetConfig::parse(&text) {
            check_config_error(&e, text.matches('\n').count() + 1);
        }
    }
}

#[test]
fn a_sentype_or_tag_that_is_no_xml_name_is_refused_with_its_line() {
    let (text, lines) = controller_file(
        49152,
        "Im\"Free",
        &[],
        &[("RKorr".into(), Some("X".into()), None)],
        false,
    );
    assert_eq!(
        EthernetConfig::parse(&text),
        Err(EthernetConfigError::NotAName {
            key: "SENTYPE",
            value: "Im\"Free".into(),
            line: 6
        })
    );
    let (text, _) = controller_file(
        49152,
        "ImFree",
        &[],
        &[("RK<orr".into(), Some("X".into()), None)],
        false,
    );
    // The '<' inside the attribute value is no XML name (and the tokenizer
    // would not see it as markup either).
    assert!(matches!(
        EthernetConfig::parse(&text),
        Err(EthernetConfigError::NotAName { key: "TAG", line, .. }) if line == lines[0]
    ));
}

/// About 10 MB of controller file: 120,000 RECEIVE elements with comments
/// between them and a deeply nested block.
fn ten_megabytes() -> String {
    let mut t = String::with_capacity(10_500_000);
    t.push_str("<ROOT><CONFIG><PORT>49152</PORT><SENTYPE>ImFree</SENTYPE></CONFIG>\n");
    t.push_str("<SEND><ELEMENTS><ELEMENT TAG=\"DEF_RSol\"/></ELEMENTS></SEND>\n");
    t.push_str("<RECEIVE><ELEMENTS>\n");
    for a in POSE_ATTRS {
        t.push_str(&format!("<ELEMENT TAG=\"RKorr.{a}\" HOLDON=\"0\"/>\n"));
    }
    let mut k = 0;
    while t.len() < 8_000_000 {
        t.push_str(&format!(
            "<ELEMENT TAG=\"Out{}.A{}\" TYPE=\"DOUBLE\" INDX=\"{k}\" HOLDON=\"0\"/><!-- {k} -->\n",
            k / 7,
            k % 7
        ));
        k += 1;
    }
    t.push_str("</ELEMENTS></RECEIVE>\n");
    while t.len() < 10_000_000 {
        t.push_str("<a>");
    }
    let depth = t.matches("<a>").count();
    for _ in 0..depth {
        t.push_str("</a>");
    }
    t.push_str("</ROOT>\n");
    t
}

#[test]
fn a_ten_megabyte_controller_file_costs_linear_work() {
    let text = ten_megabytes();
    let t0 = std::time::Instant::now();
    let (c, work) = EthernetConfig::parse_with_work(&text);
    let c = c.unwrap();
    let elapsed = t0.elapsed();
    let n = text.len() as u64;
    assert!(n >= 10_000_000);
    assert!(c.receive.len() > 100_000, "{}", c.receive.len());
    assert_eq!(c.correction_element(), Some("RKorr"));
    // Every byte is looked at a small, fixed number of times.
    assert!(work <= 4 * n, "work {work} for {n} bytes");
    // The same work for a file ten times smaller is a tenth (no hidden
    // quadratic term): the per-byte work does not grow with size.
    let small: String = {
        let mut t = text[..1_000_000].to_string();
        let cut = t.rfind("<ELEMENT").unwrap();
        t.truncate(cut);
        t.push_str("</ELEMENTS></RECEIVE></ROOT>\n");
        t
    };
    let (_, small_work) = EthernetConfig::parse_with_work(&small);
    let per_byte_big = work as f64 / n as f64;
    let per_byte_small = small_work as f64 / small.len() as f64;
    assert!(
        per_byte_big <= 1.5 * per_byte_small,
        "{per_byte_big} vs {per_byte_small}"
    );
    // The loader refuses the reply it would need, naming the limit; quickly.
    let cfg = RsiConfig {
        enabled: true,
        controllers: vec!["10.0.0.2".into()],
        ethernet_config: Some("RSI_EthernetConfig.xml".into()),
        ..RsiConfig::default()
    };
    let e = cfg.settings(Some(&text)).unwrap_err();
    assert!(
        matches!(e, ConfigError::ReplyTooLarge { limit: 65536, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("65536"), "{e}");
    // A coarse backstop only (the assertions above are on work): a
    // quadratic parser takes hours here.
    let total = t0.elapsed();
    assert!(
        total.as_secs() < 60,
        "{elapsed:?} to parse, {total:?} in all"
    );
}
