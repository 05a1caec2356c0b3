//! Unit tests of `knots`.

use super::*;

fn two() -> KnotRules {
    KnotRules::new(2)
}

fn offline_err(text: &str, n: usize, expected: &str) {
    match parse_offline("k.txt", text, &KnotRules::new(n)) {
        Ok(k) => panic!("accepted {k:?}"),
        Err(e) => assert_eq!(e.to_string(), expected),
    }
}

fn pvt_err(text: &str, n: usize, expected: &str) {
    match parse_pvt("p.txt", text, &KnotRules::new(n)) {
        Ok(k) => panic!("accepted {k:?}"),
        Err(e) => assert_eq!(e.to_string(), expected),
    }
}

#[test]
fn thesis_offline_example_parses() {
    let k =
        parse_offline("k.txt", "3\n0.0  0      0\n0.25 2000  -2000\n0.5   3000  -4500\n", &two())
            .unwrap();
    assert_eq!(k.times, [0.0, 0.25, 0.5]);
    assert_eq!(k.positions[2][..2], [3000.0, -4500.0]);
    // Tabs, CRLF and trailing blank lines, as Excel writes them.
    let k2 = parse_offline(
        "k.txt",
        "3\r\n0.0\t0\t0\r\n0.25\t2000\t-2000\r\n0.5\t3000\t-4500\r\n\r\n",
        &two(),
    )
    .unwrap();
    assert_eq!(k, k2);
}

#[test]
fn thesis_pvt_example_parses() {
    let text = "X    0    0    25.00000    Y    0    0    25.00000\n\
                X   309  16000 35.00000    Y   309  16000 35.00000\n\
                X   700  0     35.00000    Y   700  0     35.00000\n";
    let ks = parse_pvt("p.txt", text, &two()).unwrap();
    assert_eq!(ks.len(), 3);
    assert_eq!((ks[1].pos[0], ks[1].vel[1], ks[1].dt_s), (309.0, 16000.0, 0.035));
    assert_eq!(ks[0].dt_s, 0.025);
}

#[test]
fn offline_errors_are_exact() {
    offline_err(
        "",
        1,
        "k.txt:1:1: expected the number of knots on the first line, found an empty file",
    );
    offline_err(
        "three\n",
        1,
        "k.txt:1:1: expected the number of knots (a whole number), found `three`",
    );
    // Issue 28, item 8: a PVT file given to the spline says what it looks like.
    offline_err(
        "X 0 1000 10 Y 0 0 10 Z 0 0 10\n",
        1,
        "k.txt:1:1: expected the number of knots (a whole number), found `X` (it looks like a \
         PVT file: run it with --method pvt)",
    );
    offline_err(
        "3 knots\n",
        1,
        "k.txt:1:3: expected only the number of knots on the first line, found `knots` after it",
    );
    offline_err("1\n0 0\n", 1, "k.txt:1:1: a cubic spline needs at least 2 knots, the file says 1");
    offline_err(
        "2000000\n",
        1,
        "k.txt:1:1: 2000000 knots is more than the 1048576 the memory budget allows",
    );
    offline_err("3\n0 0\n1 5\n", 1, "k.txt:4:1: the first line says 3 knots but the file has 2");
    offline_err(
        "2\n0 0\n1 5\n2 7\n",
        1,
        "k.txt:4:1: the first line says 2 knots but there are more: this is knot 3",
    );
    offline_err(
        "2\n0 0 0\n1 5\n",
        3,
        "k.txt:2:6: expected 4 columns (time and 3 motor positions), found 3",
    );
    offline_err(
        "2\n0 0 0 0 9\n1 5 5 5\n",
        3,
        "k.txt:2:9: expected 4 columns (time and 3 motor positions), found 5",
    );
    offline_err("2\n0,5 0\n1 5\n", 1, "k.txt:2:1: time: expected a number of seconds, found `0,5`");
    offline_err(
        "2\n0 0\ninf 5\n",
        1,
        "k.txt:3:1: time: expected a finite number of seconds, found `inf`",
    );
    offline_err(
        "2\nNaN 0\n1 5\n",
        1,
        "k.txt:2:1: time: expected a finite number of seconds, found `NaN`",
    );
    offline_err(
        "3\n0 0\n0.5 1\n0.25 2\n",
        1,
        "k.txt:4:1: time 0.25 s is before the previous knot's 0.5 s (line 3): times must increase",
    );
    offline_err(
        "3\n0 0\n0.5 1\n0.5 2\n",
        1,
        "k.txt:4:1: time 0.5 s repeats the previous knot's time (line 3)",
    );
    offline_err(
        "2\n0 0 12.5\n1 5 5\n",
        2,
        "k.txt:2:5: motor 2 position: expected a whole number of counts, found `12.5`",
    );
    offline_err(
        "2\n0 abc\n1 5\n",
        1,
        "k.txt:2:3: motor 1 position: expected a whole number of counts, found `abc`",
    );
    offline_err(
        "2\n0 3000000000\n1 5\n",
        1,
        "k.txt:2:3: motor 1 position 3000000000 is outside the software counter's range ±2147483647 counts",
    );
}

#[test]
fn pvt_errors_are_exact() {
    let ok = "X 0 0 10";
    pvt_err(
        "X 0 0 10 Y 0 0 10\n",
        3,
        "p.txt:1:18: expected 12 columns (label, position, velocity and time for each of 3 motors), found 8",
    );
    pvt_err("XY 0 0 10\n", 1, "p.txt:1:1: motor 1 label `XY` must be one character");
    pvt_err(
        "X 0 0 10 Y 0 0 10\nX 0 0 10 Y 0 0 30\n",
        2,
        "p.txt:2:16: motor 2 time to the next knot 30 ms differs from motor 1's 10 ms: one line is one step of time for every motor",
    );
    pvt_err("X 0 0 0\n", 1, "p.txt:1:7: motor 1 time to the next knot must be > 0 ms, found 0");
    pvt_err("X 0 0 -5\n", 1, "p.txt:1:7: motor 1 time to the next knot must be > 0 ms, found -5");
    pvt_err(
        "X 0 0 inf\n",
        1,
        "p.txt:1:7: motor 1 time to the next knot: expected a finite number of ms, found `inf`",
    );
    pvt_err(
        "X 0 fast 10\n",
        1,
        "p.txt:1:5: motor 1 velocity: expected a number of counts/s, found `fast`",
    );
    pvt_err(
        "X 0 NaN 10\n",
        1,
        "p.txt:1:5: motor 1 velocity: expected a finite number of counts/s, found `NaN`",
    );
    pvt_err(
        "X 1.5 0 10\n",
        1,
        "p.txt:1:3: motor 1 position: expected a whole number of counts, found `1.5`",
    );
    pvt_err(
        "X -2147483648 0 10\n",
        1,
        "p.txt:1:3: motor 1 position -2147483648 is outside the software counter's range ±2147483647 counts",
    );
    pvt_err(&format!("{ok}\n{ok}\n"), 1, "p.txt:3:1: a PVT path needs at least 3 knots, found 2");
    pvt_err("", 1, "p.txt:1:1: a PVT path needs at least 3 knots, found 0");
    pvt_err(
        &format!("{ok}\n\n{ok}\nX 0 0\n"),
        1,
        "p.txt:4:6: expected 4 columns (label, position, velocity and time for each of 1 motor), found 3",
    );
}

#[test]
fn pvt_stream_parser_counts_lines_and_knots() {
    let mut p = PvtLineParser::new("-", &KnotRules::new(1));
    assert_eq!(p.parse_line("").unwrap(), None);
    assert!(p.parse_line("A 5 -10.5 20\r").unwrap().is_some());
    assert_eq!((p.lines(), p.knots()), (2, 1));
    assert_eq!(p.too_few().to_string(), "-:3:1: a PVT path needs at least 3 knots, found 1");
}

#[test]
fn non_utf8_is_named_with_its_line() {
    let e = text_of("k.txt", b"2\n0 0\n1 \xff\n".to_vec()).unwrap_err();
    assert_eq!(e.to_string(), "k.txt:3:3: expected text (UTF-8), found a byte that is not");
}

#[test]
fn too_large_files_are_refused_before_reading() {
    // A device's size says nothing (`/dev/zero`: 0 bytes): the read itself is bounded.
    let e = read_knot_file(Path::new("/dev/zero")).unwrap_err();
    assert_eq!(
        e.to_string(),
        "/dev/zero: the file has more than 67108864 bytes, the most a knot file may have"
    );
    let missing = read_knot_file(Path::new("/nonexistent/k.txt")).unwrap_err().to_string();
    assert!(missing.starts_with("/nonexistent/k.txt: cannot read the knot file: "), "{missing}");
}

/// Issue 10, item 1: every number that becomes a duration is bounded; a path longer than
/// `trajectory.max_duration_s` is an error naming file, line and column (a time of 1e20
/// used to overflow the sample count, one of 1e300 to spin for minutes).
#[test]
fn paths_longer_than_the_longest_are_refused() {
    offline_err(
        "2\n0 0\n1e20 5\n",
        1,
        "k.txt:3:1: time 1e20 s is 1e20 s after the first knot: longer than the longest path, \
         trajectory.max_duration_s = 86400 s",
    );
    pvt_err(
        "X 0 0 10\nX 5 0 1e300\nX 9 0 10\n",
        1,
        "p.txt:2:7: this knot's segment ends 1e297 s after the first knot: longer than the \
         longest path, trajectory.max_duration_s = 86400 s",
    );
    let short = KnotRules::new(1).max_duration_s(1.0);
    let e = parse_pvt("p.txt", "X 0 0 600\nX 5 0 600\nX 9 0 10\n", &short).unwrap_err();
    assert!(e.to_string().starts_with("p.txt:2:7: this knot's segment ends 1.2 s"), "{e}");
    assert!(parse_offline("k.txt", "2\n0 0\n1 5\n", &short).is_ok(), "1 s is allowed");
}

/// Issue 10, items 2 and 16: comments and blank lines anywhere; a byte-order mark; lines
/// and streams are bounded.
#[test]
fn comments_blank_lines_and_bounded_lines() {
    let k = parse_offline(
        "k.txt",
        "\u{feff}# a path\n\n3\n  # times in s\n0 0 0\n\n1 5 5\n# the end\n2 9 9\n",
        &two(),
    )
    .unwrap();
    assert_eq!(k.times, [0.0, 1.0, 2.0]);
    let ks =
        parse_pvt("p.txt", "\u{feff}X 0 0 10\n# two\nX 5 0 10\n\nX 9 0 10\n", &KnotRules::new(1))
            .unwrap();
    assert_eq!(ks.len(), 3);
    // Everything else stays strict: a comment after a knot is not a comment.
    pvt_err(
        "X 0 0 10 # first\n",
        1,
        "p.txt:1:10: expected 4 columns (label, position, velocity and time for each of 1 motor), found 6",
    );
    let long = format!("2\n0 0\n1 {}\n", "5".repeat(MAX_LINE_BYTES));
    offline_err(
        &long,
        1,
        "k.txt:3:1: the line has more than 4096 bytes, the most a knot line may have",
    );
    // A stream without line ends stops after the limit instead of filling the memory.
    let mut zeros = std::io::BufReader::new(std::io::repeat(0));
    let mut buf = Vec::new();
    let e = read_line_bounded(&mut zeros, &mut buf).unwrap_err();
    assert_eq!(e.kind(), std::io::ErrorKind::InvalidData);
    assert!(buf.len() <= MAX_LINE_BYTES + 2);
    let mut two_lines = std::io::Cursor::new(b"ab\r\ncd".to_vec());
    assert!(read_line_bounded(&mut two_lines, &mut buf).unwrap());
    assert_eq!(buf, b"ab");
    assert!(read_line_bounded(&mut two_lines, &mut buf).unwrap());
    assert_eq!(buf, b"cd");
    assert!(!read_line_bounded(&mut two_lines, &mut buf).unwrap());
}

/// The shipped robot's motion limits at 4× (80 000 counts/s, 5·10⁶ counts/s²) at 400 µs.
fn limited(n: usize) -> KnotRules {
    let mut r = KnotRules::new(n);
    r.max_velocity = [80_000.0; MAX_MOTORS];
    r.max_acceleration = [5e6; MAX_MOTORS];
    r
}

/// Issue 27, item 2: a PVT path that asks a motor more than its limits is refused before it
/// is used — a file before the move, a stream knot by knot (the same parser) — naming the
/// file, the line and column of the motor's velocity, and the setting it breaks.
#[test]
fn pvt_knots_beyond_the_motion_limits_are_refused_naming_line_and_motor() {
    let err = |text: &str| parse_pvt("p.txt", text, &limited(3)).unwrap_err().to_string();
    let rest = "X 0 0 10 Y 0 0 10 Z 0 0 10\n";
    // The issue's knot: 1e308 counts/s (its cubic would be NaN in the loop).
    assert_eq!(
        err(&format!("X 0 1e308 10 Y 0 0 10 Z 0 0 10\n{rest}{rest}")),
        "p.txt:1:5: motor 1: the path moves at 1e308 counts/s on its way to this knot, faster \
         than motor 1's max_velocity_counts_per_s = 80000"
    );
    // 270 000 counts/s in the middle of a path: the segment to that knot is too fast.
    assert_eq!(
        err(
            "X 0 0 10 Y 0 0 10 Z 0 0 10\nX 0 0 10 Y 0 0 10 Z 1350 270000 10\nX 0 0 10 Y 0 0 10 Z 2700 0 10\n"
        ),
        "p.txt:2:26: motor 3: the path moves at 270000 counts/s on its way to this knot, faster \
         than motor 3's max_velocity_counts_per_s = 80000"
    );
    // Slow enough (30 000 counts/s at most), but 200 counts in 10 ms and back: too hard an
    // acceleration.
    assert_eq!(
        err(
            "X 0 0 10 Y 0 0 10 Z 0 0 10\nX 0 0 10 Y 200 0 10 Z 0 0 10\nX 0 0 10 Y 0 0 10 Z 0 0 10\n"
        ),
        "p.txt:2:16: motor 2: the path accelerates at 1.2e7 counts/s² on its way to this knot, \
         more than motor 2's max_acceleration_counts_per_s2 = 5000000"
    );
    // The thesis' own knots (A.2.3.2) are well within the limits, and without limits nothing
    // is checked.
    let thesis = "X 0 0 25 Y 0 0 25\nX 309 16000 35 Y 309 16000 35\nX 700 0 35 Y 700 0 35\n";
    assert!(parse_pvt("p.txt", thesis, &limited(2)).is_ok());
    assert!(
        parse_pvt(
            "p.txt",
            &format!("X 0 1e308 10 Y 0 0 10 Z 0 0 10\n{rest}{rest}"),
            &KnotRules::new(3)
        )
        .is_ok()
    );
}
