//! End-to-end tests of the `vcsmooth` binary: every command on generated meshes, the JSON and SVG
//! it writes, and the one-line errors (with no output file) on bad input.

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::util::{
    arg, command, fails, generate_sphere, json, listing, ok, read_json, scan, vcsmooth,
};

const METHODS: [&str; 5] = ["vcs", "vcs-triangle", "lem", "laplacian", "taubin"];

fn svg_texts(path: &Path) -> Vec<String> {
    let svg = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        svg.contains("<svg") && svg.contains("</svg>"),
        "not an SVG: {}",
        path.display()
    );
    svg.lines().map(|l| l.trim().to_string()).collect()
}

/// A noisy 642-vertex sphere (`--subdivisions 3`) in a fresh directory.
fn noisy_sphere_file() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("noisy.ply");
    generate_sphere(&path, 3, Some(0.3), Some(7));
    (dir, path)
}

#[test]
fn info_json_of_generated_sphere() {
    let (_dir, sphere) = noisy_sphere_file();
    let info = json(&ok(vcsmooth([
        "info".as_ref(),
        sphere.as_os_str(),
        "--json".as_ref(),
    ])));
    assert_eq!(info["vertices"], 642);
    assert_eq!(info["triangles"], 1280);
    assert_eq!(info["closed"], true);
    assert_eq!(info["boundary_edges"], 0);
    assert!(info["volume"].as_f64().unwrap() > 3.0, "{info}");

    let table = ok(vcsmooth(["info".as_ref(), sphere.as_os_str()]));
    assert!(table.contains("642") && table.contains("closed"), "{table}");
}

/// An ASCII PLY of `points` (as `double`) and `triangles`.
fn double_ply(points: &[[f64; 3]], triangles: &[[u32; 3]]) -> String {
    let mut text = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty double x\nproperty double y\n\
         property double z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        points.len(),
        triangles.len()
    );
    for [x, y, z] in points {
        text += &format!("{x} {y} {z}\n");
    }
    for [a, b, c] in triangles {
        text += &format!("3 {a} {b} {c}\n");
    }
    text
}

/// `generate mesh --from` a file keeps its precision: a millimetre grid far from the origin
/// (geographic coordinates) stays `double` and keeps its area.
#[test]
fn generate_from_a_double_mesh_stays_double() {
    let dir = tempfile::tempdir().unwrap();
    let points = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
        .map(|(x, y)| [6378137.0 + x * 1e-3, 4000000.125 + y * 1e-3, 0.5]);
    let text = double_ply(&points, &[[0, 1, 2], [0, 2, 3]]);
    let (geo, out) = (dir.path().join("geo.ply"), dir.path().join("g.ply"));
    std::fs::write(&geo, text).unwrap();
    for levels in ["0", "2"] {
        ok(vcsmooth([
            "generate".as_ref(),
            "mesh".as_ref(),
            out.as_os_str(),
            "--from".as_ref(),
            geo.as_os_str(),
            "--subdivide".as_ref(),
            levels.as_ref(),
            "--noise".as_ref(),
            "0".as_ref(),
        ]));
        let header = std::fs::read(&out).unwrap();
        assert!(header.windows(17).any(|w| w == b"property double x"));
        let area = |p: &Path| {
            json(&ok(vcsmooth([
                "info".as_ref(),
                p.as_os_str(),
                "--json".as_ref(),
            ])))["area"]
                .as_f64()
                .unwrap()
        };
        let (a0, a1) = (area(&geo), area(&out));
        assert!((a1 / a0 - 1.0).abs() < 1e-6, "{levels}: area {a0} -> {a1}");
    }
}

#[test]
fn generate_torus_is_closed() {
    let dir = tempfile::tempdir().unwrap();
    let torus = dir.path().join("torus.obj");
    ok(vcsmooth([
        "generate".as_ref(),
        "torus".as_ref(),
        torus.as_os_str(),
        "--subdivisions".as_ref(),
        "1".as_ref(),
    ]));
    let info = json(&ok(vcsmooth([
        "info".as_ref(),
        torus.as_os_str(),
        "--json".as_ref(),
    ])));
    assert_eq!(info["closed"], true);
    assert_eq!(info["triangles"], 1024);
}

#[test]
fn smooth_with_each_method_writes_mesh_report_and_plot() {
    let (dir, sphere) = noisy_sphere_file();
    let iterations = 4;
    for method in METHODS {
        let out = dir.path().join(format!("{method}.ply"));
        let report = dir.path().join(format!("{method}.json"));
        let plot = dir.path().join(format!("{method}.svg"));
        let text = ok(vcsmooth([
            "smooth".as_ref(),
            sphere.as_os_str(),
            out.as_os_str(),
            "--method".as_ref(),
            method.as_ref(),
            "--iterations".as_ref(),
            iterations.to_string().as_ref(),
            "--report".as_ref(),
            report.as_os_str(),
            "--plot".as_ref(),
            plot.as_os_str(),
        ]));
        assert!(out.is_file(), "{method}: no output mesh");
        assert!(
            text.contains("volume %"),
            "{method}: no table on stdout: {text}"
        );

        let r = read_json(&report);
        assert_eq!(r["options"]["method"], method);
        assert_eq!(r["options"]["iterations"], iterations);
        assert!(r["tool"]["version"].is_string());
        assert_eq!(r["results_version"], vcsmooth::RESULTS_VERSION);
        assert_eq!(r["input"]["stats"]["vertices"], 642);
        assert_eq!(r["output"]["stats"]["vertices"], 642);
        assert_eq!(r["output"]["stats"]["closed"], true);
        assert!(r["plan"]["patches"].as_u64().unwrap() >= 1);
        assert!(r["plan"]["colours"].as_u64().unwrap() >= 1);
        assert!(r["memory"]["peak_anon"].as_u64().unwrap() > 0);
        assert_eq!(r["memory"]["storage"], "heap");
        assert!(r["memory"]["bytes_read"].as_u64().unwrap() > 0);
        assert!(r["memory"]["bytes_written"].as_u64().unwrap() > 0);
        for phase in [
            "ingest",
            "reorder",
            "topology",
            "partition",
            "smoothing",
            "write",
        ] {
            assert!(
                r["timings"][phase].as_f64().unwrap() >= 0.0,
                "{method}: timing {phase}"
            );
        }
        let rows = r["iterations"].as_array().unwrap();
        assert_eq!(rows.len(), iterations, "{method}: iteration rows");
        for (i, row) in rows.iter().enumerate() {
            assert_eq!(row["iteration"], i + 1);
            for key in [
                "volume_pct",
                "area_pct",
                "max_displacement",
                "mean_displacement",
                "seconds",
            ] {
                assert!(
                    row[key].as_f64().unwrap().is_finite(),
                    "{method}: {key} in {row}"
                );
            }
            assert!(
                row["stencils"]["applied"].as_u64().unwrap() > 0,
                "{method}: {row}"
            );
        }
        let last = rows.last().unwrap()["volume_pct"].as_f64().unwrap();
        if method.starts_with("vcs") {
            assert!(
                (last - 100.0).abs() < 1e-6,
                "{method} lost volume: {last} %"
            );
        }
        if method == "laplacian" {
            assert!(last < 95.0, "laplacian should shrink: {last} %");
        }

        let texts = svg_texts(&plot);
        assert!(
            texts.iter().any(|t| t == method),
            "{method} not named in its plot"
        );
        assert!(texts.iter().any(|t| t == "iteration"), "no x axis label");

        // The smoothed file reads back with the same connectivity.
        let cmp = json(&ok(vcsmooth([
            "compare".as_ref(),
            sphere.as_os_str(),
            out.as_os_str(),
            "--json".as_ref(),
        ])));
        assert!(
            cmp["rms_distance"].as_f64().unwrap() > 0.0,
            "{method} moved nothing"
        );
        if method.starts_with("vcs") {
            assert!(
                (cmp["volume_ratio"].as_f64().unwrap() - 1.0).abs() < 1e-5,
                "{method}: {cmp}"
            );
        }
    }
}

/// An open mesh's signed volume depends on the point it is measured about: the report measures
/// input and output about the input's centroid (`volume_origin`), so their ratio is the
/// summary's `volume_pct` (up to the output file's `float` rounding), not off by the centroid's
/// move.
#[test]
fn an_open_meshs_report_volumes_compare() {
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("r.json");
    ok(vcsmooth([
        "smooth".as_ref(),
        scan("stanford-bunny.ply").as_os_str(),
        dir.path().join("out.ply").as_os_str(),
        "--method".as_ref(),
        "vcs".as_ref(),
        "--iterations".as_ref(),
        "10".as_ref(),
        "--report".as_ref(),
        report.as_os_str(),
    ]));
    let r = read_json(&report);
    let (input, output) = (&r["input"]["stats"], &r["output"]["stats"]);
    assert_eq!(input["closed"], false);
    assert_eq!(input["volume_origin"], output["volume_origin"]);
    let ratio = 100.0 * output["volume"].as_f64().unwrap() / input["volume"].as_f64().unwrap();
    let pct = r["summary"]["volume_pct"].as_f64().unwrap();
    assert!((ratio - pct).abs() < 1e-5, "{ratio} % against {pct} %");
}

/// `compare` and `refine` measure an open mesh's volumes about one point (the first mesh's
/// centroid), so that a volume-keeping smoothing compares as kept and a subdivision (which adds
/// vertices, moving their centroid, but not the surface) as unchanged.
#[test]
fn compare_and_refine_keep_an_open_meshs_volume() {
    let dir = tempfile::tempdir().unwrap();
    // A bumpy open 6 × 6 grid, its centroid far from the plane's: the origin matters.
    let points: Vec<[f64; 3]> = (0..36u32)
        .map(|k| {
            let (x, y) = (k % 6, k / 6);
            let z = 0.2 * ((k * 7919 % 13) as f64 / 6.0 - 1.0) + 0.05 * x as f64;
            [x as f64, y as f64, z]
        })
        .collect();
    let triangles: Vec<[u32; 3]> = (0..25u32)
        .flat_map(|q| {
            let v = q / 5 * 6 + q % 5;
            [[v, v + 1, v + 7], [v, v + 7, v + 6]]
        })
        .collect();
    let text = double_ply(&points, &triangles);
    let grid = dir.path().join("grid.ply");
    std::fs::write(&grid, text).unwrap();
    let out = dir.path().join("out.ply");
    let run = |args: &[&std::ffi::OsStr]| ok(vcsmooth(args));
    run(&[
        "smooth".as_ref(),
        grid.as_os_str(),
        out.as_os_str(),
        "--method".as_ref(),
        "vcs".as_ref(),
        "--iterations".as_ref(),
        "5".as_ref(),
    ]);
    let c = json(&run(&[
        "compare".as_ref(),
        grid.as_os_str(),
        out.as_os_str(),
        "--json".as_ref(),
    ]));
    let ratio = c["volume_ratio"].as_f64().unwrap();
    assert!((ratio - 1.0).abs() < 1e-9, "volume ratio {ratio}");
    let text = run(&[
        "refine".as_ref(),
        grid.as_os_str(),
        dir.path().join("r.ply").as_os_str(),
        "--max-edge".as_ref(),
        "0.6".as_ref(),
        "--rounds".as_ref(),
        "1".as_ref(),
    ]);
    assert!(
        text.contains("volume after subdivision 100.000000000 %"),
        "{text}"
    );
}

#[test]
fn smooth_defaults_and_other_formats() {
    let (dir, sphere) = noisy_sphere_file();
    for ext in ["obj", "off", "stl"] {
        let out = dir.path().join(format!("out.{ext}"));
        let text = ok(vcsmooth([
            "smooth".as_ref(),
            sphere.as_os_str(),
            out.as_os_str(),
        ]));
        assert!(out.is_file(), "no .{ext} output");
        // Default: vcs-lowpass, 10 iterations.
        assert!(text.contains("vcs-lowpass, 10 iterations"), "{text}");
    }
}

#[test]
fn the_default_method_says_when_to_choose_another() {
    let (dir, sphere) = noisy_sphere_file();
    let out = dir.path().join("out.ply");
    let run = |extra: &[&str]| {
        let mut args = vec!["smooth".to_string(), arg(&sphere), arg(&out)];
        args.extend(extra.iter().map(|s| s.to_string()));
        ok(vcsmooth(&args))
    };
    let hint = "--method vcs-guided";
    let text = run(&[]);
    let last = text.lines().last().unwrap();
    assert!(
        last.starts_with("method: vcs-lowpass (the default)") && last.contains(hint),
        "{text}"
    );
    // Named (even the default), with creases, or with nothing done: no hint.
    for extra in [
        &["--method", "vcs-lowpass"][..],
        &["--method", "taubin"],
        &["--crease-angle", "40"],
        &["--iterations", "0"],
        &["--multires"],
    ] {
        let text = run(extra);
        assert!(!text.contains(hint), "{extra:?}: {text}");
    }
}

#[test]
fn compare_with_itself_is_zero() {
    let (_dir, sphere) = noisy_sphere_file();
    let c = json(&ok(vcsmooth([
        "compare".as_ref(),
        sphere.as_os_str(),
        sphere.as_os_str(),
        "--json".as_ref(),
    ])));
    for key in [
        "rms_distance",
        "max_distance",
        "rms_relative",
        "max_relative",
        "mean_normal_angle_deg",
    ] {
        assert_eq!(c[key].as_f64(), Some(0.0), "{key}: {c}");
    }
    assert_eq!(c["volume_ratio"].as_f64(), Some(1.0));
    assert_eq!(c["area_ratio"].as_f64(), Some(1.0));
    let table = ok(vcsmooth([
        "compare".as_ref(),
        sphere.as_os_str(),
        sphere.as_os_str(),
    ]));
    assert!(table.contains("rms distance"), "{table}");
}

#[test]
fn curves_plot_names_every_method() {
    let (dir, sphere) = noisy_sphere_file();
    let plot = dir.path().join("curves.svg");
    let out = ok(vcsmooth([
        "curves".as_ref(),
        sphere.as_os_str(),
        "--methods".as_ref(),
        "vcs,lem,laplacian".as_ref(),
        "--iterations".as_ref(),
        "6".as_ref(),
        "--plot".as_ref(),
        plot.as_os_str(),
        "--json".as_ref(),
    ]));
    let doc = json(&out);
    let curves = doc["curves"].as_array().unwrap();
    let names: Vec<&str> = curves
        .iter()
        .map(|c| c["method"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["vcs", "lem", "laplacian"]);
    let last = |i: usize| {
        let v = curves[i]["volume_pct"].as_array().unwrap();
        assert_eq!(v.len(), 7, "iterations 0..=6");
        assert_eq!(v[0].as_f64(), Some(100.0));
        v[6].as_f64().unwrap()
    };
    let (vcs, lem, lap) = (last(0), last(1), last(2));
    assert!((vcs - 100.0).abs() < 1e-6, "vcs {vcs}");
    assert!(lap < lem && lem < 100.0, "laplacian {lap}, lem {lem}");

    let texts = svg_texts(&plot);
    for name in [
        "vcs",
        "lem",
        "laplacian",
        "iteration",
        "volume (% of input)",
    ] {
        assert!(texts.iter().any(|t| t == name), "'{name}' not in the SVG");
    }

    // The table form: a header naming each method and rows 0..=6.
    let table = ok(vcsmooth([
        "curves".as_ref(),
        sphere.as_os_str(),
        "--iterations".as_ref(),
        "6".as_ref(),
        "--plot".as_ref(),
        plot.as_os_str(),
    ]));
    let header = table.lines().next().unwrap();
    for name in ["vcs", "lem", "laplacian"] {
        assert!(header.contains(name), "{header}");
    }
    assert!(
        table.lines().any(|l| l.trim_start().starts_with("6 ")),
        "{table}"
    );
}

/// `curves` runs each method as `smooth` does: with the same flags (creases, deviation bound,
/// patches), each curve is the volume column of `smooth`'s report, bit for bit.
#[test]
fn curves_take_every_control_as_smooth_does() {
    let dir = tempfile::tempdir().unwrap();
    let fandisk = scan("denoising/Fandisk0.3-noisy.ply");
    let plot = dir.path().join("curves.svg");
    let controls = [
        "--crease-angle",
        "40",
        "--max-deviation",
        "0.01",
        "--patch-size",
        "512",
    ];
    let curve_of = |extra: &[&str]| -> Vec<Vec<f64>> {
        let mut args = vec![
            "curves",
            fandisk.to_str().unwrap(),
            "--methods",
            "vcs,laplacian,hc",
        ];
        args.extend([
            "--iterations",
            "4",
            "--plot",
            plot.to_str().unwrap(),
            "--json",
        ]);
        args.extend(extra);
        let doc = json(&ok(vcsmooth(args)));
        let pct = |c: &serde_json::Value| -> Vec<f64> {
            let v = c["volume_pct"].as_array().unwrap();
            v.iter().map(|x| x.as_f64().unwrap()).collect()
        };
        doc["curves"].as_array().unwrap().iter().map(pct).collect()
    };
    let with = curve_of(&controls);
    for (method, curve) in ["vcs", "laplacian", "hc"].iter().zip(&with) {
        let (out, report) = (dir.path().join("out.ply"), dir.path().join("r.json"));
        let mut args = vec!["smooth", fandisk.to_str().unwrap(), out.to_str().unwrap()];
        args.extend(["--method", method, "--iterations", "4"]);
        args.extend(["--report", report.to_str().unwrap()]);
        args.extend(controls);
        ok(vcsmooth(args));
        let doc = read_json(&report);
        let smooth: Vec<f64> = doc["iterations"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["volume_pct"].as_f64().unwrap())
            .collect();
        assert_eq!(curve[1..], smooth[..], "{method}");
    }
    // The creases keep the Fandisk's edges: the Laplacian shrinks it less.
    let without = curve_of(&controls[2..]);
    assert!(
        with[1][4] > without[1][4],
        "{} vs {}",
        with[1][4],
        without[1][4]
    );
}

/// `curves --iterations auto --pin FILE`: each method stops where `smooth --iterations auto`
/// stops, with the same pins, and its curve is that run's volume column; the pins take effect.
#[test]
fn curves_take_the_automatic_stop_and_pins_as_smooth_does() {
    let (dir, sphere) = noisy_sphere_file();
    let plot = dir.path().join("curves.svg");
    let pins = dir.path().join("pins.txt");
    let listed: String = (0..200).map(|i| format!("{}\n", 3 * i)).collect();
    std::fs::write(&pins, listed).unwrap();
    let methods = ["taubin", "vcs", "laplacian"];
    let curves_of = |extra: &[&str]| -> serde_json::Value {
        let mut args = vec!["curves", sphere.to_str().unwrap(), "--methods"];
        args.extend(["taubin,vcs,laplacian", "--iterations", "auto", "--json"]);
        // `smooth`'s order of the vertices (the automatic stop's noise sample follows it).
        args.extend(["--plot", plot.to_str().unwrap(), "--patch-size", "512"]);
        args.extend(extra);
        json(&ok(vcsmooth(args)))
    };
    let pct = |c: &serde_json::Value| -> Vec<f64> {
        let v = c["volume_pct"].as_array().unwrap();
        v.iter().map(|x| x.as_f64().unwrap()).collect()
    };
    let doc = curves_of(&["--pin", pins.to_str().unwrap()]);
    assert_eq!(doc["auto_stop"], true);
    let curves: Vec<Vec<f64>> = doc["curves"].as_array().unwrap().iter().map(pct).collect();
    let longest = curves.iter().map(|c| c.len() - 1).max().unwrap();
    assert_eq!(doc["iterations"].as_u64().unwrap() as usize, longest);
    for (method, curve) in methods.iter().zip(&curves) {
        let (out, report) = (dir.path().join("out.ply"), dir.path().join("r.json"));
        let mut args = vec!["smooth", sphere.to_str().unwrap(), out.to_str().unwrap()];
        args.extend([
            "--method",
            method,
            "--iterations",
            "auto",
            "--patch-size",
            "512",
        ]);
        args.extend(["--pin", pins.to_str().unwrap()]);
        args.extend(["--report", report.to_str().unwrap()]);
        ok(vcsmooth(args));
        let smooth: Vec<f64> = read_json(&report)["iterations"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["volume_pct"].as_f64().unwrap())
            .collect();
        assert!(smooth.len() < 100, "{method}: the stop never came");
        assert_eq!(curve[1..], smooth[..], "{method}");
    }
    // Without the pins the Laplacian's curve differs: they were applied.
    let free = curves_of(&[]);
    let laplacian = pct(&free["curves"][2]);
    assert_ne!(laplacian[1], curves[2][1]);
}

/// A reader that closes standard output early (`| head -1`) ends the command quietly: its files
/// written, its own exit code (0, or the tolerance's), nothing on stderr.
#[test]
fn a_closed_stdout_ends_quietly_with_the_commands_own_code() {
    let (dir, sphere) = noisy_sphere_file();
    let out = dir.path().join("out.ply");
    let closed = |args: &[&str]| {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        command().args(args).stdout(writer).output().unwrap()
    };
    let s = sphere.to_str().unwrap();
    for (args, code) in [
        (vec!["info", s], 0),
        (vec!["smooth", s, out.to_str().unwrap()], 0),
        (
            vec!["smooth", s, out.to_str().unwrap(), "--tolerance", "1e-9"],
            3,
        ),
    ] {
        let _ = std::fs::remove_file(&out);
        let o = closed(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{args:?}: {err}");
        assert!(!err.contains("error"), "{args:?}: {err}");
        if args[0] == "smooth" {
            assert!(out.exists(), "{args:?}: no output");
        }
    }
}

#[test]
fn missing_input_fails_cleanly_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (missing, out) = (dir.path().join("missing.ply"), dir.path().join("out.ply"));
    let (report, plot) = (dir.path().join("r.json"), dir.path().join("p.svg"));
    let o = vcsmooth([
        "smooth".as_ref(),
        missing.as_os_str(),
        out.as_os_str(),
        "--report".as_ref(),
        report.as_os_str(),
        "--plot".as_ref(),
        plot.as_os_str(),
    ]);
    fails(&o, 1, &["missing.ply"]);
    assert!(
        listing(dir.path()).is_empty(),
        "left files: {:?}",
        listing(dir.path())
    );

    fails(
        &vcsmooth(["info".as_ref(), missing.as_os_str()]),
        1,
        &["missing.ply"],
    );
    fails(
        &vcsmooth(["compare".as_ref(), missing.as_os_str(), missing.as_os_str()]),
        1,
        &["missing.ply"],
    );
    let o = vcsmooth([
        "curves".as_ref(),
        missing.as_os_str(),
        "--plot".as_ref(),
        plot.as_os_str(),
    ]);
    fails(&o, 1, &["missing.ply"]);
    assert!(listing(dir.path()).is_empty());
}

#[test]
fn corrupt_input_fails_cleanly_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.ply");
    std::fs::write(&bad, b"ply\nformat binary_little_endian 1.0\nelement vertex 100\nproperty float x\nend_header\n\x01\x02").unwrap();
    let (out, report, plot) = (
        dir.path().join("out.ply"),
        dir.path().join("r.json"),
        dir.path().join("p.svg"),
    );
    let o = vcsmooth([
        "smooth".as_ref(),
        bad.as_os_str(),
        out.as_os_str(),
        "--report".as_ref(),
        report.as_os_str(),
        "--plot".as_ref(),
        plot.as_os_str(),
    ]);
    fails(&o, 1, &["bad.ply"]);
    assert_eq!(listing(dir.path()), ["bad.ply"]);
}

#[test]
fn usage_errors_fail_cleanly_and_write_nothing() {
    let (dir, sphere) = noisy_sphere_file();
    let out = dir.path().join("out.ply");
    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        (vec!["--method", "median"], &["median"]),
        (vec!["--iterations", "abc"], &["--iterations", "abc"]),
        (vec!["--iterations", "-1"], &["--iterations"]),
        (vec!["--lambda", "nan"], &["--lambda"]),
        (vec!["--threads", "0"], &["--threads"]),
        (vec!["--plot", "volume.png"], &["volume.png", "svg"]),
        (vec!["--bogus"], &["--bogus"]),
    ];
    for (extra, mentions) in cases {
        let mut args: Vec<&std::ffi::OsStr> =
            vec!["smooth".as_ref(), sphere.as_os_str(), out.as_os_str()];
        args.extend(extra.iter().map(std::ffi::OsStr::new));
        fails(&vcsmooth(&args), 2, mentions);
        assert!(!out.exists(), "{extra:?} wrote the output");
    }

    let xyz = dir.path().join("out.xyz");
    fails(
        &vcsmooth(["smooth".as_ref(), sphere.as_os_str(), xyz.as_os_str()]),
        2,
        &["out.xyz", "format"],
    );
    let nodir = dir.path().join("no").join("such").join("out.ply");
    fails(
        &vcsmooth(["smooth".as_ref(), sphere.as_os_str(), nodir.as_os_str()]),
        2,
        &["does not exist"],
    );
    // A trailing slash names a directory: refused before the run, not when writing after it.
    let slash = format!("{}/", dir.path().join("o1.ply").display());
    fails(
        &vcsmooth(["smooth".as_ref(), sphere.as_os_str(), slash.as_ref()]),
        2,
        &["o1.ply/", "ends with '/'"],
    );
    assert!(!dir.path().join("o1.ply").exists());
    fails(
        &vcsmooth(["smooth".as_ref(), sphere.as_os_str()]),
        2,
        &["OUT"],
    );
    fails(&vcsmooth(["frobnicate"]), 2, &["frobnicate"]);
    let big = dir.path().join("big.ply");
    let o = vcsmooth([
        "generate".as_ref(),
        "sphere".as_ref(),
        big.as_os_str(),
        "--subdivisions".as_ref(),
        "30".as_ref(),
    ]);
    fails(&o, 1, &["--subdivisions 30"]);
    let o = vcsmooth([
        "generate".as_ref(),
        "sphere".as_ref(),
        xyz.as_os_str(),
        "--subdivisions".as_ref(),
        "1".as_ref(),
    ]);
    fails(&o, 2, &["out.xyz"]);
    let svg = dir.path().join("c.svg");
    let o = vcsmooth([
        "curves".as_ref(),
        sphere.as_os_str(),
        "--plot".as_ref(),
        svg.as_os_str(),
        "--methods".as_ref(),
        "vcs,nope".as_ref(),
    ]);
    fails(&o, 2, &["nope"]);
    assert_eq!(listing(dir.path()), ["noisy.ply"]);
}

#[test]
fn compare_of_different_meshes_fails() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.ply"), dir.path().join("b.ply"));
    for (p, k) in [(&a, 1), (&b, 2)] {
        generate_sphere(p, k, None, None);
    }
    fails(
        &vcsmooth(["compare".as_ref(), a.as_os_str(), b.as_os_str()]),
        1,
        &["b.ply"],
    );
}

#[test]
fn help_lists_commands_and_defaults() {
    let top = ok(vcsmooth(["--help"]));
    for cmd in ["smooth", "info", "compare", "generate", "curves"] {
        assert!(top.contains(cmd), "{cmd} missing from --help");
    }
    let smooth = ok(vcsmooth(["smooth", "--help"]));
    for s in [
        "[default: vcs-lowpass; with --multires, vcs]",
        "[default: 10]",
        "[default: 0.5]",
        "[default: -0.53 for taubin, -0.52 for vcs-lowpass]",
        "--reject-energy-increase",
        "--threads",
        "--report",
        "--plot",
    ] {
        assert!(smooth.contains(s), "'{s}' missing from smooth --help");
    }
    assert!(ok(vcsmooth(["--version"])).contains(env!("CARGO_PKG_VERSION")));
}

/// `vcs-lowpass` through the command line: the output file is bit-identical for 1 and 3 threads
/// and between in-core and the smallest memory budget (scratch-mapped arrays), and the volume is
/// kept; every block is applied.
#[test]
fn vcs_lowpass_output_identical_across_threads_and_memory_budgets() {
    let dir = tempfile::tempdir().unwrap();
    let scratch = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    // Level 8 (1.3M triangles) is the smallest sphere whose in-core estimate exceeds the 64M minimum.
    generate_sphere(&input, 8, Some(0.3), None);
    let sdir = scratch.path().display().to_string();
    let run_as = |name: &str, ext: &str, extra: &[&str]| -> (Vec<u8>, Value) {
        let out = dir.path().join(format!("{name}.{ext}"));
        let report = dir.path().join(format!("{name}.json"));
        let mut args: Vec<String> = [
            "smooth",
            &input.display().to_string(),
            &out.display().to_string(),
            "--method",
            "vcs-lowpass",
            "--iterations",
            "1",
            "--patch-size",
            "4096",
            "--report",
            &report.display().to_string(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        args.extend(extra.iter().map(|s| s.to_string()));
        ok(vcsmooth(&args));
        (std::fs::read(&out).unwrap(), read_json(&report))
    };
    let run = |name: &str, extra: &[&str]| run_as(name, "ply", extra);
    let (one, r1) = run("t1", &["--threads", "1"]);
    assert_eq!(r1["memory"]["storage"], "heap");
    let it = &r1["iterations"][0];
    // Patches of 4096 vertices: one block each, every one applied.
    assert_eq!(
        it["stencils"]["applied"].as_u64().unwrap(),
        655_362u64.div_ceil(4096)
    );
    // Percent of the input's volume: 1e-7 % is 1e-9 relative.
    assert!(
        (it["volume_pct"].as_f64().unwrap() - 100.0).abs() < 1e-7,
        "{it}"
    );
    let (three, _) = run("t3", &["--threads", "3"]);
    assert!(three == one, "--threads 3 differs from --threads 1");
    let (mapped, rm) = run(
        "mapped",
        &[
            "--memory-budget",
            "64M",
            "--scratch",
            &sdir,
            "--threads",
            "2",
        ],
    );
    assert_eq!(rm["memory"]["storage"], "scratch");
    assert!(mapped == one, "scratch-mapped run differs from in-core");
    // Out of core the λ step is kept for the patches' border alone (each patch takes its other
    // vertices' as it starts). The peak is the topology build's since the smoothing finds the
    // faces in the triangles' runs (12 B per triangle less); it was the smoothing's, the arrays of `vcs`'s (see
    // `smooth_output_identical_across_threads_and_memory_budgets`) but the seam (the blocks
    // measure their own moves), and the border's steps (24 B and a 4 B id for each of the 11 % of
    // the vertices with a neighbour in another patch at this patch size): 56.0 B per triangle,
    // where the step of every vertex made 66.5.
    let m = rm["input"]["stats"]["triangles"].as_u64().unwrap();
    let peak = rm["memory"]["scratch_peak_bytes"].as_u64().unwrap();
    assert!(
        2 * peak <= 113 * m,
        "peak {peak} = {} B per triangle",
        peak / m
    );
}

/// Issue #33: the report's `disk` gives the bytes read and written in every phase and in all,
/// from `/proc/self/io` (null where it cannot be read); an out-of-core run prints its sweep's
/// per iteration.
#[test]
fn the_report_gives_the_disk_traffic_of_each_phase() {
    const PHASES: [&str; 9] = [
        "ingest",
        "reorder",
        "topology",
        "partition",
        "smoothing",
        "restore",
        "write",
        "metrics",
        "deviation",
    ];
    const FIGURES: [&str; 5] = [
        "disk_read_bytes",
        "disk_written_bytes",
        "disk_write_cancelled_bytes",
        "syscall_read_bytes",
        "syscall_written_bytes",
    ];
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    // Level 8 (1.3M triangles) is the smallest sphere whose in-core estimate exceeds the 64M minimum.
    generate_sphere(&input, 8, Some(0.3), None);
    let scratch = dir.path().display().to_string();
    let runs: [(&str, &[&str]); 2] = [
        ("heap", &["--deviation-field"]),
        (
            "scratch",
            &["--memory-budget", "64M", "--scratch", &scratch],
        ),
    ];
    for (storage, extra) in runs {
        let out = dir.path().join(format!("{storage}.ply"));
        let report = dir.path().join(format!("{storage}.json"));
        let mut args = vec![
            "smooth".to_string(),
            input.display().to_string(),
            out.display().to_string(),
            "--iterations".into(),
            "2".into(),
            "--report".into(),
            report.display().to_string(),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        let text = ok(vcsmooth(&args));
        let r = read_json(&report);
        assert_eq!(r["memory"]["storage"], storage);
        let disk = &r["disk"];
        if std::fs::read_to_string("/proc/self/io").is_err() {
            assert!(disk.is_null(), "{disk}");
            continue;
        }
        // Non-negative integers, and the phases, one after another, within the total.
        for figure in FIGURES {
            let of = |phase: &str| {
                disk[phase][figure]
                    .as_u64()
                    .unwrap_or_else(|| panic!("{storage}: disk.{phase}.{figure} in {disk}"))
            };
            let phases: u64 = PHASES.iter().map(|p| of(p)).sum();
            assert!(
                phases <= of("total"),
                "{storage}: {figure} of the phases {phases} > total {}",
                of("total")
            );
        }
        // The output goes out through write(2), all of it whatever the file system; on a disk
        // its pages are dirtied too, where tmpfs counts none (its tempdir may be one).
        let size = std::fs::metadata(&out).unwrap().len();
        let write = &disk["write"];
        assert!(
            write["syscall_written_bytes"].as_u64().unwrap() >= size,
            "{storage}: {write}, output {size} B"
        );
        let dirtied = write["disk_written_bytes"].as_u64().unwrap();
        assert!(
            dirtied == 0 || dirtied >= size,
            "{storage}: {write}, output {size} B"
        );
        assert_eq!(
            text.contains("disk per iteration: "),
            storage == "scratch",
            "{text}"
        );
    }
}

/// Issue 3: the output file is bit-identical for 1, 2 and 8 threads, and between in-core and the
/// smallest memory budget (scratch-mapped arrays), for a fixed patch size; scratch files vanish.
#[test]
fn smooth_output_identical_across_threads_and_memory_budgets() {
    let dir = tempfile::tempdir().unwrap();
    let scratch = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    // Level 8 (1.3M triangles) is the smallest sphere whose in-core estimate exceeds the 64M minimum.
    generate_sphere(&input, 8, Some(0.3), None);
    let run_as = |name: &str, ext: &str, extra: &[&str]| -> (Vec<u8>, Value) {
        let out = dir.path().join(format!("{name}.{ext}"));
        let report = dir.path().join(format!("{name}.json"));
        let mut args: Vec<String> = vec![
            "smooth".into(),
            input.display().to_string(),
            out.display().to_string(),
            "--method".into(),
            "vcs".into(),
            "--iterations".into(),
            "1".into(),
            "--patch-size".into(),
            "4096".into(),
            "--report".into(),
            report.display().to_string(),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        ok(vcsmooth(&args));
        (std::fs::read(&out).unwrap(), read_json(&report))
    };
    let run = |name: &str, extra: &[&str]| run_as(name, "ply", extra);
    let (one, r1) = run("t1", &["--threads", "1"]);
    assert_eq!(r1["memory"]["storage"], "heap");
    assert!(r1["plan"]["colours"].as_u64().unwrap() > 1);
    assert!(r1["plan"]["crossing_edge_stencils"].as_u64().unwrap() > 0);
    assert_eq!(
        r1["iterations"][0]["stencils"]["applied"].as_u64().unwrap()
            + r1["iterations"][0]["stencils"]["skipped_fixed"]
                .as_u64()
                .unwrap()
            + r1["iterations"][0]["stencils"]["skipped_degenerate"]
                .as_u64()
                .unwrap()
            + r1["iterations"][0]["stencils"]["rejected"]
                .as_u64()
                .unwrap(),
        r1["input"]["stats"]["edges"].as_u64().unwrap(),
        "every edge stencil considered exactly once"
    );
    for threads in ["2", "8"] {
        let (out, _) = run(&format!("t{threads}"), &["--threads", threads]);
        assert!(out == one, "--threads {threads} differs from --threads 1");
    }
    let sdir = scratch.path().display().to_string();
    let (mapped, rm) = run("mapped", &["--memory-budget", "64M", "--scratch", &sdir]);
    assert_eq!(rm["memory"]["storage"], "scratch");
    let all = rm["memory"]["scratch_bytes"].as_u64().unwrap();
    let peak = rm["memory"]["scratch_peak_bytes"].as_u64().unwrap();
    assert!(all > 64 << 20);
    // Arrays are given back as the run goes: the disk never holds all of them at once, and at
    // least the positions and triangles are held together.
    let (n, m) = (
        rm["input"]["stats"]["vertices"].as_u64().unwrap(),
        rm["input"]["stats"]["triangles"].as_u64().unwrap(),
    );
    assert!(
        peak < all && peak >= 24 * n + 12 * m,
        "peak {peak}, all {all}"
    );
    // The input's arrays go once the plan has its copy, the triangles and adjacency before the
    // positions are put back in the input's order (the output, binary, measured before), and the
    // plan before the input is read again for the write; the components are counted before the
    // adjacency is built. The peak (a closed mesh, n ≈ m / 2) is the topology build's, the
    // smoothing's below it since it finds the faces in the triangles' runs (no vertex → face
    // list): the f64 positions (24 B per vertex; no copy: the patches measure
    // their moves, and out of core the neighbour sums are each patch's own), the plan's
    // triangles and both adjacency lists (36 B per triangle), one array of offsets (8 B per
    // vertex: on a closed manifold it serves both lists, and the build keeps each vertex's
    // neighbours less faces in a byte), the permutation and the mask (5 B per vertex), the seam
    // (about 8 B for each of a few % of the vertices at this patch size): 55.3 B per triangle,
    // where the copy made 66.5.
    assert!(
        2 * peak <= 111 * m,
        "peak {peak} = {} B per triangle",
        peak / m
    );
    assert!(mapped == one, "scratch-mapped run differs from in-core");
    // Outputs measured after the restore (text, rounded in place) or whose normals come from the
    // positions (STL): the same bytes in core and out of core.
    for ext in ["stl", "obj"] {
        let (heap, _) = run_as("heap", ext, &[]);
        let (mapped, _) = run_as(
            "mapped",
            ext,
            &["--memory-budget", "64M", "--scratch", &sdir],
        );
        assert!(
            heap == mapped,
            "{ext}: scratch-mapped run differs from in-core"
        );
    }
    assert_eq!(
        std::fs::read_dir(scratch.path()).unwrap().count(),
        0,
        "scratch left behind"
    );

    let o = vcsmooth([
        "smooth",
        &input.display().to_string(),
        &dir.path().join("x.ply").display().to_string(),
        "--memory-budget",
        "1M",
    ]);
    fails(&o, 2, &["--memory-budget", "minimum"]);
    assert!(!dir.path().join("x.ply").exists());
}

/// The memory budget holds what the tool itself adds: every per-vertex structure (a file of
/// 920k unreferenced vertices beside a sphere ran in core at 1.13× an 80 MiB budget, its size
/// saying it fitted) and every per-patch one (the schedule of `--patch-size 1` took 1.79 GiB at a
/// 64 MiB budget). Vertices are counted from the PLY header, a schedule that cannot fit is refused
/// before any work naming a patch size that fits, and that size runs within the budget.
#[test]
fn the_memory_budget_counts_vertices_and_patches() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = vcsmooth::shapes::icosphere(6);
    let mut crowded = sphere.clone();
    crowded.positions.extend(
        (0..920_000u32).map(|i| glam::DVec3::new(5.0 + f64::from(i % 97), f64::from(i / 97), 7.0)),
    );
    crowded.source.precision = vcsmooth::io::Precision::Float;
    let input = dir.path().join("crowded.ply");
    vcsmooth::io::write_mesh(&input, &crowded).unwrap();
    // 12 B per vertex: by its size alone (the model's 19 B per triangle) it would fit in core.
    assert!(std::fs::metadata(&input).unwrap().len() < 13 << 20);
    let out = dir.path().join("out.ply");
    let report = dir.path().join("r.json");
    let s = |p: &Path| p.display().to_string();
    let run = |input: &Path, extra: &[&str]| {
        let mut args = vec![
            "smooth".to_string(),
            s(input),
            s(&out),
            "--iterations".into(),
            "2".into(),
            "--report".into(),
            s(&report),
        ];
        args.extend(extra.iter().map(|a| a.to_string()));
        vcsmooth(&args)
    };
    for (budget, bytes) in [("80M", 80u64 << 20), ("128M", 128 << 20)] {
        ok(run(&input, &["--memory-budget", budget]));
        let r = read_json(&report);
        let peak = r["memory"]["peak_anon"].as_u64().unwrap();
        assert!(
            peak <= bytes,
            "{budget}: peak {peak} in {}",
            r["memory"]["storage"]
        );
    }

    let small = dir.path().join("sphere.ply");
    vcsmooth::io::write_mesh(&small, &sphere).unwrap();
    std::fs::remove_file(&out).unwrap();
    let o = run(&small, &["--memory-budget", "64M", "--patch-size", "1"]);
    fails(
        &o,
        1,
        &[
            "--patch-size 1",
            "40962 patches",
            "schedule",
            "memory budget",
        ],
    );
    assert!(!out.exists(), "a refused plan wrote an output");
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    let fits = err
        .split("use a patch size of ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .unwrap_or_else(|| panic!("no patch size named: {err}"));
    assert!(fits.parse::<usize>().unwrap() > 1, "{err}");
    for method in ["vcs", "taubin"] {
        ok(run(
            &small,
            &[
                "--memory-budget",
                "64M",
                "--patch-size",
                fits,
                "--method",
                method,
            ],
        ));
        let r = read_json(&report);
        let peak = r["memory"]["peak_anon"].as_u64().unwrap();
        assert!(
            peak <= 64 << 20,
            "{method} at --patch-size {fits}: peak {peak}"
        );
        assert!(r["plan"]["patches"].as_u64().unwrap() > 1000);
    }
}

/// `generate mesh --from MESH --subdivide L` streams a refined scan: 4^L times the triangles,
/// closed like its base, the same volume (flat subdivision); misuse is a one-line usage error.
#[test]
fn generate_mesh_from_a_scan_streams_a_refined_copy() {
    let dir = tempfile::tempdir().unwrap();
    let base = scan("fertility-9k.ply");
    let out = dir.path().join("fine.ply");
    ok(vcsmooth([
        "generate",
        "mesh",
        &out.display().to_string(),
        "--from",
        &base.display().to_string(),
        "--subdivide",
        "2",
    ]));
    let fine = json(&ok(vcsmooth([
        "info",
        &out.display().to_string(),
        "--json",
    ])));
    let coarse = json(&ok(vcsmooth([
        "info",
        &base.display().to_string(),
        "--json",
    ])));
    assert_eq!(fine["triangles"], 9000 * 16);
    assert_eq!(fine["closed"], true);
    assert_eq!(fine["components"], 1);
    assert_eq!(fine["non_manifold_vertices"], 0);
    let (v0, v1) = (
        coarse["volume"].as_f64().unwrap(),
        fine["volume"].as_f64().unwrap(),
    );
    assert!(((v1 - v0) / v0).abs() < 1e-6, "{v0} vs {v1}");

    let o = vcsmooth([
        "generate",
        "mesh",
        &dir.path().join("x.ply").display().to_string(),
    ]);
    fails(&o, 2, &["--from"]);
    let o = vcsmooth([
        "generate",
        "mesh",
        &dir.path().join("x.obj").display().to_string(),
        "--from",
        &base.display().to_string(),
        "--subdivide",
        "1",
    ]);
    fails(&o, 2, &["--subdivide", "PLY"]);
    assert!(!dir.path().join("x.ply").exists() && !dir.path().join("x.obj").exists());
}

#[test]
fn stats_last_measures_only_the_last_iteration_and_changes_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    generate_sphere(&input, 3, Some(0.3), None);
    for method in METHODS {
        let mut outputs = Vec::new();
        let mut reports = Vec::new();
        for stats in ["every", "last"] {
            let out = dir.path().join(format!("{method}-{stats}.ply"));
            let report = dir.path().join(format!("{method}-{stats}.json"));
            let text = ok(vcsmooth([
                "smooth",
                input.to_str().unwrap(),
                out.to_str().unwrap(),
                "--method",
                method,
                "--iterations",
                "3",
                "--stats",
                stats,
                "--report",
                report.to_str().unwrap(),
            ]));
            if stats == "last" {
                // The table shows '-' for what was not measured.
                let row = text
                    .lines()
                    .find(|l| l.trim_start().starts_with("1 "))
                    .unwrap();
                assert!(row.contains(" - "), "{method}: {row}");
            }
            outputs.push(std::fs::read(&out).unwrap());
            reports.push(read_json(&report));
        }
        assert!(outputs[0] == outputs[1], "{method}: outputs differ");
        let (every, last) = (&reports[0]["iterations"], &reports[1]["iterations"]);
        for i in 0..2 {
            assert!(last[i]["volume_pct"].is_null() && last[i]["area_pct"].is_null());
            assert_eq!(last[i]["stencils"], every[i]["stencils"], "{method}");
        }
        for key in ["volume", "volume_pct", "area_pct", "max_displacement"] {
            assert_eq!(last[2][key], every[2][key], "{method}: {key}");
        }
        assert_eq!(
            reports[0]["summary"]["volume_pct"],
            reports[1]["summary"]["volume_pct"]
        );
    }
    let plot = dir.path().join("p.svg");
    let o = vcsmooth([
        "smooth",
        input.to_str().unwrap(),
        dir.path().join("o.ply").to_str().unwrap(),
        "--stats",
        "last",
        "--plot",
        plot.to_str().unwrap(),
    ]);
    fails(&o, 2, &["--plot", "--stats every"]);
}

/// `generate mesh` streams binary PLY whatever the output's extension says, so any other output is
/// refused before any work (it once wrote PLY bytes into an `.obj` file).
#[test]
fn generate_mesh_refuses_a_non_ply_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.obj");
    let kitten = scan("kitten-25k.ply");
    let o = vcsmooth([
        "generate",
        "mesh",
        out.to_str().unwrap(),
        "--from",
        kitten.to_str().unwrap(),
    ]);
    fails(&o, 2, &["x.obj", ".ply output"]);
    assert!(listing(dir.path()).is_empty(), "{:?}", listing(dir.path()));
}

/// A run in which most vertices cannot move says so in one warning line, with why and what to
/// try; one in which none can says its output has the input's positions. A triangle soup (every
/// corner its own vertex, as an unmerged STL or a texture-seamed file) is welded and smoothed
/// like the sphere it comes from; with `--no-weld` it fixes every vertex; a closed sphere warns of
/// nothing. The report carries the counts (`plan.fixed`).
#[test]
fn a_run_says_when_most_vertices_cannot_move() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = crate::util::noisy_sphere(3, 0.3, 5);
    let soup = vcsmooth::Mesh::new(
        sphere
            .triangles
            .iter()
            .flat_map(|t| t.map(|v| sphere.positions[v as usize]))
            .collect(),
        (0..sphere.triangles.len() as u32)
            .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
            .collect(),
    );
    let (closed, loose) = (dir.path().join("closed.ply"), dir.path().join("soup.ply"));
    vcsmooth::io::write_mesh(&closed, &sphere).unwrap();
    vcsmooth::io::write_mesh(&loose, &soup).unwrap();
    let out = dir.path().join("out.ply");
    let report = dir.path().join("r.json");
    let run = |input: &Path, extra: &[&str]| {
        let mut args = vec![
            "smooth".to_string(),
            input.display().to_string(),
            out.display().to_string(),
            "--iterations".into(),
            "2".into(),
            "--report".into(),
            report.display().to_string(),
        ];
        args.extend(extra.iter().map(|a| a.to_string()));
        let o = vcsmooth(&args);
        assert_eq!(
            o.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    let err = run(&closed, &[]);
    assert!(!err.contains("warning"), "{err}");
    assert_eq!(read_json(&report)["plan"]["fixed"]["fixed"], 0);

    // Welded (the default): every copy moves, each with the others of its position, as the
    // sphere's vertex does (Taubin's sums read the same neighbours, in another order).
    let n = soup.positions.len();
    let smoothed = |input: &Path| {
        run(input, &["--method", "taubin"]);
        vcsmooth::io::read_mesh(&out).unwrap().positions
    };
    let (whole, welded) = (smoothed(&closed), smoothed(&loose));
    for (k, t) in sphere.triangles.iter().enumerate() {
        for c in 0..3 {
            let (a, b) = (welded[3 * k + c], whole[t[c] as usize]);
            assert!((a - b).length() < 1e-12, "corner {c} of {k}: {a} vs {b}");
        }
    }
    let err = run(&loose, &[]);
    assert!(!err.contains("warning"), "{err}");
    let r = read_json(&report);
    assert_eq!(r["plan"]["fixed"]["fixed"], 0);
    assert_eq!(
        r["plan"]["fixed"]["welded"].as_u64(),
        Some((n - sphere.positions.len()) as u64)
    );
    let (v0, v1) = (
        r["input"]["stats"]["volume"].as_f64().unwrap(),
        r["output"]["stats"]["volume"].as_f64().unwrap(),
    );
    // Exact before the write; the file stores single precision.
    assert!(((v1 - v0) / v0).abs() < 1e-7, "{v0} -> {v1}");

    let err = run(&loose, &["--no-weld"]);
    let lines: Vec<&str> = err.lines().filter(|l| l.contains("warning")).collect();
    assert_eq!(lines.len(), 1, "{err}");
    for part in [
        "vcsmooth: warning: ",
        "soup.ply: ",
        &format!("none of the {n} vertices can move"),
        "boundary edges",
        "without --no-weld",
        "--boundary smooth",
    ] {
        assert!(lines[0].contains(part), "{part}: {}", lines[0]);
    }
    let r = read_json(&report);
    assert_eq!(r["plan"]["fixed"]["fixed"].as_u64(), Some(n as u64));
    assert_eq!(
        r["plan"]["fixed"]["boundary_edges"].as_u64(),
        Some(n as u64)
    );
    assert!(std::fs::read(&out).is_ok());

    // Corners an exporter rounded apart (each copy a few micrometres off; edges are about 0.1):
    // exact welding leaves them, and the warning says how to weld them; a tolerance welds them.
    let mut rounded = soup.clone();
    for (i, p) in rounded.positions.iter_mut().enumerate() {
        *p += glam::DVec3::new(1.0, -1.0, 0.5) * (i % 3) as f64 * 2e-6;
    }
    let jittered = dir.path().join("rounded.ply");
    vcsmooth::io::write_mesh(&jittered, &rounded).unwrap();
    let err = run(&jittered, &[]);
    assert!(
        err.contains("none of the") && err.contains("--weld-tolerance D"),
        "{err}"
    );
    let err = run(&jittered, &["--weld-tolerance", "1e-4"]);
    assert!(!err.contains("warning"), "{err}");
    let r = read_json(&report);
    assert_eq!(r["options"]["weld_tolerance"].as_f64(), Some(1e-4));
    assert_eq!(
        r["plan"]["fixed"]["welded"].as_u64(),
        Some((n - sphere.positions.len()) as u64)
    );
    let info = crate::util::ok(vcsmooth([
        "info",
        &jittered.display().to_string(),
        "--weld-tolerance",
        "1e-4",
    ]));
    assert!(info.contains("boundary edges         0"), "{info}");
    let o = vcsmooth([
        "smooth",
        &jittered.display().to_string(),
        &out.display().to_string(),
        "--no-weld",
        "--weld-tolerance",
        "1e-4",
    ]);
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );

    // Most vertices pinned: the warning names the pins.
    let pins = dir.path().join("pins.txt");
    let many: String = (0..sphere.positions.len() * 3 / 4)
        .map(|i| format!("{i}\n"))
        .collect();
    std::fs::write(&pins, many).unwrap();
    let err = run(&closed, &["--pin", &pins.display().to_string()]);
    assert!(
        err.contains("cannot move freely") && err.contains("pinned") && err.contains("pin fewer"),
        "{err}"
    );
}

/// A conversion that cannot carry what the input had says so in one note, and the report lists
/// it; the same format keeps everything and says nothing.
#[test]
fn a_conversion_says_what_it_drops() {
    let dir = tempfile::tempdir().unwrap();
    for f in ["textured.obj", "textured.mtl"] {
        std::fs::copy(
            crate::util::scan(&format!("fidelity/{f}")),
            dir.path().join(f),
        )
        .unwrap();
    }
    let input = dir.path().join("textured.obj");
    let report = dir.path().join("r.json");
    let run = |out: &str| {
        let o = vcsmooth([
            "smooth",
            &input.display().to_string(),
            &dir.path().join(out).display().to_string(),
            "--report",
            &report.display().to_string(),
        ]);
        assert_eq!(o.status.code(), Some(0));
        let err = String::from_utf8_lossy(&o.stderr).to_string();
        let notes: Vec<String> = err
            .lines()
            .filter(|l| l.starts_with("vcsmooth: note: "))
            .map(String::from)
            .collect();
        (notes, read_json(&report)["output"]["dropped"].clone())
    };
    let (notes, dropped) = run("out.ply");
    assert_eq!(notes.len(), 1, "{notes:?}");
    for part in [
        "out.ply: written without the input's texture coordinates, colours, normals, materials",
        "PLY written from OBJ",
        "write .obj to keep them",
    ] {
        assert!(notes[0].contains(part), "{part}: {}", notes[0]);
    }
    assert_eq!(dropped[0], "texture coordinates");
    let (notes, _) = run("out.stl");
    assert!(
        notes[0].contains("polygons (written as their triangles)"),
        "{notes:?}"
    );
    let (notes, dropped) = run("out.obj");
    assert!(notes.is_empty(), "{notes:?}");
    assert!(dropped.is_null(), "{dropped}");
}
