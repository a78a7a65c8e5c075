//! RINEX 3.04 against RINEX 2: the GEONET station 0759 files of tests/data/gnss/rtklib
//! (RINEX 2.10) are rewritten here as RINEX 3.04 text, field by field, copying the
//! real file's number strings (no number is re-formatted), with the RINEX 3 traps
//! added: a continued `SYS / # / OBS TYPES`, a second system whose satellites must be
//! skipped, codes in the header but blank for every satellite, the file's own splice
//! events (flag 4 with comment lines), `IONOSPHERIC CORR` lines of other systems, and
//! GLONASS and Galileo navigation records of 4 and 8 lines. Reading both versions must
//! give the same ephemerides and the same converted epochs.

use std::path::PathBuf;

use navguard_core::epoch::{Constellation, Epoch, SatId};
use navguard_formats::ephemeris::GalileoMessage;
use navguard_formats::rinex::convert::{RinexParams, convert};
use navguard_formats::rinex::nav::{NavFile, parse_nav, read_nav};
use navguard_formats::rinex::obs::{ObsFile, parse_obs, read_obs};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/gnss")
        .join(rel)
}

fn text(rel: &str) -> String {
    std::fs::read_to_string(data(rel)).unwrap()
}

/// A header line: content in columns 1–60, label from 61.
fn hl(content: &str, label: &str) -> String {
    format!("{content:<60}{label}")
}

fn is_label(line: &str, label: &str) -> bool {
    line.get(60..).map(str::trim) == Some(label)
}

/// Columns `a..b`, padded with blanks past the end of a right-trimmed line.
fn field(line: &str, a: usize, b: usize) -> String {
    format!(
        "{:<w$}",
        line.get(a..b.min(line.len())).unwrap_or(""),
        w = b - a
    )
}

/// The GPS codes of the RINEX 3 file: 14, so the list is continued on a second line.
const G_TYPES: [&str; 14] = [
    "C1C", "L1C", "D1C", "S1C", "C1W", "L1W", "C2W", "L2W", "C2L", "L2L", "C5Q", "L5Q", "D5Q",
    "S5Q",
];

/// The RINEX 2.10 observation text (types L1 C1 L2 P2, one line per satellite) as
/// RINEX 3.04: C1→C1C, L1→L1C, P2→C2W, L2→L2W, the other G codes blank, and a
/// Galileo satellite added to every fifth epoch. With `c1w`, C1W is filled with
/// C1 + `c1w` m (the only re-formatted numbers).
fn obs2_to_3(v2: &str, c1w: Option<f64>) -> String {
    let lines: Vec<&str> = v2.lines().collect();
    assert!(is_label(lines[11], "# / TYPES OF OBSERV"));
    assert_eq!(
        lines[11].split_whitespace().take(5).collect::<Vec<_>>(),
        ["4", "L1", "C1", "L2", "P2"]
    );
    let end = lines
        .iter()
        .position(|l| is_label(l, "END OF HEADER"))
        .unwrap();
    let approx = lines
        .iter()
        .find(|l| is_label(l, "APPROX POSITION XYZ"))
        .unwrap();
    let mut out = vec![
        hl(
            "     3.04           OBSERVATION DATA    M",
            "RINEX VERSION / TYPE",
        ),
        hl("converted from 07590920.05o in a test", "COMMENT"),
        approx.to_string(),
    ];
    let types = |t: &[&str]| t.iter().map(|c| format!(" {c}")).collect::<String>();
    out.push(hl(
        &format!("G  {:3}{}", G_TYPES.len(), types(&G_TYPES[..13])),
        "SYS / # / OBS TYPES",
    ));
    out.push(hl(
        &format!("      {}", types(&G_TYPES[13..])),
        "SYS / # / OBS TYPES",
    ));
    out.push(hl("E    2 C1C L1C", "SYS / # / OBS TYPES"));
    out.push(hl("", "END OF HEADER"));
    let mut k = end + 1;
    let mut epoch = 0;
    while k < lines.len() {
        let l = lines[k];
        let flag = &l[28..29];
        let n: usize = l[29..32].trim().parse().unwrap();
        if flag == "4" {
            out.push(format!(">{:30}4{n:3}", ""));
            out.extend(lines[k + 1..=k + n].iter().map(|s| s.to_string()));
            k += 1 + n;
            continue;
        }
        assert_eq!(flag, "0", "line {}", k + 1);
        assert!(n <= 12);
        let d: Vec<&str> = l[0..26].split_whitespace().collect();
        let num = |s: &str| s.parse::<u32>().unwrap();
        let galileo = epoch % 5 == 0;
        out.push(format!(
            "> {} {:02} {:02} {:02} {:02}{:>11}  0{:3}",
            2000 + num(d[0]),
            num(d[1]),
            num(d[2]),
            num(d[3]),
            num(d[4]),
            d[5],
            n + usize::from(galileo)
        ));
        for j in 0..n {
            let sat = &l[32 + 3 * j..35 + 3 * j];
            assert_eq!(&sat[..1], "G");
            let prn: u32 = sat[1..].trim().parse().unwrap();
            let line = lines[k + 1 + j];
            let f = |i: usize| field(line, 16 * i, 16 * i + 16);
            let blank = " ".repeat(16);
            let c1w = c1w.map_or(blank.clone(), |dx| {
                let c1: f64 = f(1)[..14].trim().parse().unwrap();
                format!("{:14.3}  ", c1 + dx)
            });
            let values = [
                f(1),
                f(0),
                blank.clone(),
                blank.clone(),
                c1w,
                blank.clone(),
                f(3),
                f(2),
            ];
            out.push(
                format!("G{prn:02}{}", values.concat())
                    .trim_end()
                    .to_string(),
            );
            if galileo && j == 1 {
                out.push("E11  23456789.123 7 123456789.12345".to_string());
            }
        }
        k += 1 + n;
        epoch += 1;
    }
    out.join("\n") + "\n"
}

/// The RINEX 2.10 GPS navigation text as RINEX 3.04 (mixed): `ION ALPHA`/`ION BETA`
/// as `GPSA`/`GPSB`, each record's first line re-headed `Gnn yyyy mm dd hh mm ss`,
/// the orbit lines indented by one more column, `D` exponents as `E`; after the first
/// GPS record a GLONASS record, to be skipped, and a Galileo one (an F/NAV record by its
/// data sources, 2), to be kept.
fn nav2_to_3(v2: &str) -> String {
    let lines: Vec<&str> = v2.lines().collect();
    let end = lines
        .iter()
        .position(|l| is_label(l, "END OF HEADER"))
        .unwrap();
    let find = |label: &str| *lines.iter().find(|l| is_label(l, label)).unwrap();
    let mut out = vec![
        hl(
            "     3.04           N: GNSS NAV DATA    M: MIXED",
            "RINEX VERSION / TYPE",
        ),
        hl(
            &format!("GPSA {}", &find("ION ALPHA")[2..50]),
            "IONOSPHERIC CORR",
        ),
        hl(
            &format!("GPSB {}", &find("ION BETA")[2..50]),
            "IONOSPHERIC CORR",
        ),
        hl(
            "GAL    6.6250E+01 -1.6406E-01 -2.4414E-04  0.0000E+00",
            "IONOSPHERIC CORR",
        ),
        find("LEAP SECONDS").to_string(),
        hl("", "END OF HEADER"),
    ];
    let body = &lines[end + 1..];
    assert_eq!(body.len() % 8, 0);
    for (r, rec) in body.chunks(8).enumerate() {
        let first = rec[0];
        let prn: u32 = first[0..2].trim().parse().unwrap();
        let d: Vec<&str> = first[2..22].split_whitespace().collect();
        let num = |s: &str| s.parse::<u32>().unwrap();
        let sec: f64 = d[5].parse().unwrap();
        assert_eq!(sec.fract(), 0.0);
        out.push(
            format!(
                "G{prn:02} {} {:02} {:02} {:02} {:02} {:02}{}",
                2000 + num(d[0]),
                num(d[1]),
                num(d[2]),
                num(d[3]),
                num(d[4]),
                sec as u32,
                &first[22..]
            )
            .replace('D', "E"),
        );
        out.extend(rec[1..].iter().map(|l| format!(" {l}").replace('D', "E")));
        if r == 0 {
            out.extend(
                [
                    "R05 2005 04 02 00 15 00 1.234567890123E-05 0.000000000000E+00 8.100000000000E+04",
                    "     1.234567890123E+04 1.234567890123E+00 0.000000000000E+00 0.000000000000E+00",
                    "     1.234567890123E+04 1.234567890123E+00 0.000000000000E+00 1.000000000000E+00",
                    "     1.234567890123E+04 1.234567890123E+00 0.000000000000E+00 0.000000000000E+00",
                    "E11 2005 04 02 00 10 00 1.234567890123E-04 0.000000000000E+00 0.000000000000E+00",
                ]
                .map(str::to_string),
            );
            for _ in 0..7 {
                out.push(
                    "     1.000000000000E+00 2.000000000000E+00 3.000000000000E+00 4.000000000000E+00"
                        .to_string(),
                );
            }
        }
    }
    out.join("\n") + "\n"
}

fn obs2() -> ObsFile {
    read_obs(&data("rtklib/07590920.05o")).unwrap()
}

fn nav2() -> NavFile {
    read_nav(&data("rtklib/07590920.05n")).unwrap()
}

fn obs3(c1w: Option<f64>) -> ObsFile {
    parse_obs(
        &obs2_to_3(&text("rtklib/07590920.05o"), c1w),
        "0759.05O.rnx",
    )
    .unwrap()
}

fn nav3() -> NavFile {
    parse_nav(&nav2_to_3(&text("rtklib/07590920.05n")), "0759.05N.rnx").unwrap()
}

/// The two conversions agree: same times and satellites, pseudoranges, positions,
/// clocks and Klobuchar delays to 1e-6 m; returns how many satellites were compared.
fn assert_same(a: &[Epoch], b: &[Epoch]) -> usize {
    assert_eq!(a.len(), b.len());
    let mut n = 0;
    for (ea, eb) in a.iter().zip(b) {
        assert_eq!(ea.t, eb.t);
        let (sa, sb) = (
            &ea.gnss_raw.as_ref().unwrap().sats,
            &eb.gnss_raw.as_ref().unwrap().sats,
        );
        assert_eq!(sa.len(), sb.len(), "t = {}", ea.t);
        for (x, y) in sa.iter().zip(sb) {
            assert_eq!(x.id, y.id);
            let close = |p: f64, q: f64| assert!((p - q).abs() < 1e-6, "{} {p} vs {q}", x.id);
            close(x.pr, y.pr);
            close(x.clk, y.clk);
            (0..3).for_each(|i| close(x.pos[i], y.pos[i]));
            close(x.iono.unwrap_or(0.0), y.iono.unwrap_or(0.0));
            assert_eq!(x.iono.is_some(), y.iono.is_some());
            n += 1;
        }
    }
    n
}

#[test]
fn rinex3_nav_gives_the_rinex2_ephemerides_keeps_galileo_and_skips_glonass() {
    let (v2, v3) = (nav2(), nav3());
    assert_eq!(v3.ephemerides.len(), 162 + 1);
    for prn in 1..=32 {
        let sat = SatId {
            constellation: Constellation::Gps,
            prn,
        };
        assert_eq!(v3.ephemerides.of(sat), v2.ephemerides.of(sat), "{sat}");
    }
    let e11 = SatId {
        constellation: Constellation::Galileo,
        prn: 11,
    };
    let gal = v3.ephemerides.of(e11)[0].galileo.unwrap();
    assert_eq!(gal.message, GalileoMessage::FNav);
    assert_eq!(
        (gal.sisa_m, gal.bgd_e1_e5a, gal.bgd_e1_e5b),
        (1.0, 3.0, 4.0)
    );
    assert_eq!(v3.klobuchar, v2.klobuchar);
    assert!(v3.klobuchar.is_some());
    assert_eq!(v3.leap_seconds, Some(13.0));
    assert_eq!(v3.other_systems_skipped, 1);
    assert_eq!(v2.other_systems_skipped, 0);
}

#[test]
fn rinex3_obs_keeps_gps_and_galileo_and_skips_the_splice_events() {
    let (v2, v3) = (obs2(), obs3(None));
    assert_eq!(v3.types, G_TYPES);
    assert_eq!(v3.galileo_types, ["C1C", "L1C"]);
    assert_eq!(v3.approx_position, v2.approx_position);
    assert_eq!(v3.epochs.len(), 120);
    assert_eq!(v3.events_skipped, 3);
    assert_eq!(v3.other_systems_skipped, 0);
    let galileo = |s: &&(SatId, _)| s.0.constellation == Constellation::Galileo;
    let e11: usize = v3
        .epochs
        .iter()
        .map(|e| e.sats.iter().filter(galileo).count())
        .sum();
    assert_eq!(e11, 24);
    let e = v3.epochs[0].sats.iter().find(galileo).unwrap();
    assert_eq!(
        e.1[0].map(|o| (o.value, o.ssi)),
        Some((23_456_789.123, Some(7)))
    );
    for (a, b) in v2.epochs.iter().zip(&v3.epochs) {
        assert_eq!(a.t, b.t);
        let gps: Vec<_> = b.sats.iter().filter(|s| !galileo(s)).collect();
        assert_eq!(
            a.sats.iter().map(|s| s.0).collect::<Vec<_>>(),
            gps.iter().map(|s| s.0).collect::<Vec<_>>()
        );
        for ((_, x), (_, y)) in a.sats.iter().zip(gps) {
            // C1 = C1C, L1 = L1C, P2 = C2W, L2 = L2W, with LLI and SSI.
            assert_eq!((x[1], x[0], x[3], x[2]), (y[0], y[1], y[6], y[7]));
            assert!(y[4].is_none() && y[8..].iter().all(Option::is_none));
        }
    }
}

#[test]
fn rinex3_converts_to_the_rinex2_pseudoranges_orbits_and_clocks() {
    let (o2, n2, o3, n3) = (obs2(), nav2(), obs3(None), nav3());
    for iono_free in [false, true] {
        let p = RinexParams {
            iono_free,
            truth_approx_position: true,
        };
        let a = convert(&o2, &n2, "v2", p).unwrap();
        let b = convert(&o3, &n3, "v3", p).unwrap();
        // E11's 24 observations are dropped: its record's health is 2 (and it has no
        // E5a code for the iono-free pair).
        assert_eq!(a.dropped + 24, b.dropped);
        let n = assert_same(&a.epochs, &b.epochs);
        eprintln!("iono_free {iono_free}: {n} satellite observations agree");
        assert!(n > 900, "{n}");
    }
}

#[test]
fn rinex3_iono_free_prefers_c1w_and_single_frequency_c1c() {
    // C1W = C1C + 0.5 m: iono-free moves by f1²/(f1² − f2²)·0.5 m, L1 alone not at all.
    let (o2, n2, o3, n3) = (obs2(), nav2(), obs3(Some(0.5)), nav3());
    let p = |iono_free| RinexParams {
        iono_free,
        truth_approx_position: true,
    };
    let single = |o: &ObsFile, n: &NavFile| convert(o, n, "x", p(false)).unwrap().epochs;
    assert_same(&single(&o2, &n2), &single(&o3, &n3));
    let a = convert(&o2, &n2, "v2", p(true)).unwrap().epochs;
    let b = convert(&o3, &n3, "v3", p(true)).unwrap().epochs;
    let gamma = 1575.42f64.powi(2) / (1575.42f64.powi(2) - 1227.6f64.powi(2));
    for (ea, eb) in a.iter().zip(&b) {
        let sats = |e: &Epoch| e.gnss_raw.clone().unwrap().sats;
        for (x, y) in sats(ea).iter().zip(&sats(eb)) {
            assert!(
                ((y.pr - x.pr) - gamma * 0.5).abs() < 1e-6,
                "{}",
                y.pr - x.pr
            );
        }
    }
}

/// The error of parsing `text` as observation (`obs`) or navigation text.
fn error_of(text: &str, obs: bool) -> String {
    if obs {
        parse_obs(text, "bad.rnx").unwrap_err().to_string()
    } else {
        parse_nav(text, "bad.rnx").unwrap_err().to_string()
    }
}

/// `text` with line `n` (1-based) replaced by `f(line)`.
fn edit(text: &str, n: usize, f: impl Fn(&str) -> String) -> String {
    text.lines()
        .enumerate()
        .map(|(i, l)| if i + 1 == n { f(l) } else { l.to_string() })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The 1-based number of the first line satisfying `p`.
fn line_no(text: &str, p: impl Fn(&str) -> bool) -> usize {
    text.lines().position(p).unwrap() + 1
}

#[test]
fn rinex3_malformed_lines_are_named_by_file_and_line() {
    let obs = obs2_to_3(&text("rtklib/07590920.05o"), None);
    // A pseudorange with a letter in it, in the third satellite line of epoch 2.
    let second_epoch = obs
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with('>'))
        .nth(1);
    let n = second_epoch.unwrap().0 + 1 + 3;
    let bad = edit(&obs, n, |l| format!("{}x{}", &l[..8], &l[9..]));
    let e = error_of(&bad, true);
    assert!(e.starts_with(&format!("bad.rnx:{n}: not a number")), "{e}");
    // An observation line where an epoch record is due (one satellite too many).
    let first = line_no(&obs, |l| l.starts_with('>'));
    let bad = edit(&obs, first, |l| format!("{}{:3}", &l[..32], 7));
    let e = error_of(&bad, true);
    assert!(
        e.starts_with(&format!("bad.rnx:{}: expected an epoch record", first + 8)),
        "{e}"
    );
    // A satellite count that runs into the next epoch.
    let bad = edit(&obs, first, |l| format!("{}{:3}", &l[..32], 10));
    let e = error_of(&bad, true);
    assert!(
        e.starts_with(&format!("bad.rnx:{}: expected a satellite", first + 10)),
        "{e}"
    );
    // A type count that does not match its list.
    let sys = line_no(&obs, |l| l.starts_with("G   14"));
    let bad = edit(&obs, sys, |l| l.replacen("G   14", "G   15", 1));
    let e = error_of(&bad, true);
    assert!(e.contains("count of 'G' does not match"), "{e}");

    let nav = nav2_to_3(&text("rtklib/07590920.05n"));
    // A bad exponent on the fourth broadcast-orbit line of the second GPS record.
    let second = nav
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with('G') && l.as_bytes()[1].is_ascii_digit())
        .nth(1)
        .unwrap()
        .0
        + 1;
    let bad = edit(&nav, second + 4, |l| l.replacen('E', "Q", 1));
    let e = error_of(&bad, false);
    assert!(
        e.starts_with(&format!("bad.rnx:{}: not a number", second + 4)),
        "{e}"
    );
    // A GPS record cut to 6 orbit lines.
    let bad: String = nav
        .lines()
        .enumerate()
        .filter(|(i, _)| *i + 1 != second + 7)
        .map(|(_, l)| format!("{l}\n"))
        .collect();
    let e = error_of(&bad, false);
    assert!(
        e.starts_with(&format!("bad.rnx:{}: G", second + 7))
            && e.contains(&format!(" record of line {second} cut short")),
        "{e}"
    );
}

#[test]
fn unknown_rinex_versions_and_types_are_clear_errors() {
    let obs = obs2_to_3(&text("rtklib/07590920.05o"), None);
    let nav = nav2_to_3(&text("rtklib/07590920.05n"));
    for (text, is_obs) in [(&obs, true), (&nav, false)] {
        let v4 = edit(text, 1, |l| l.replacen("3.04", "4.01", 1));
        let e = error_of(&v4, is_obs);
        assert_eq!(
            e,
            "bad.rnx:1: RINEX version '4.01' is not read (only 2.x and 3.x are)"
        );
        let no_version = edit(text, 1, |_| hl("", "COMMENT"));
        let e = error_of(&no_version, is_obs);
        assert_eq!(e, "bad.rnx:1: the first line is not RINEX VERSION / TYPE");
    }
    // A navigation file given as observations, and the reverse.
    assert!(error_of(&nav, true).starts_with("bad.rnx:1: not an observation file"));
    assert!(error_of(&obs, false).starts_with("bad.rnx:1: not a navigation file"));
}
