//! Seeded random scenarios for the planner's simulator test: layouts of blocks, their shades
//! against the scene's lighting, and the scenario TOML built on a shipped scenario.

use handeye_vision::rng::SplitMix64;

use super::Camera;

/// One block of a generated layout.
#[derive(Debug, Clone)]
pub struct BlockLayout {
    pub kind: &'static str,
    pub size_mm: [f64; 3],
    pub position_m: [f64; 2],
    pub yaw_deg: f64,
    /// Albedo per face, in the simulator's face order of the kind.
    pub shades: Vec<f64>,
}

/// Where random blocks are placed: the shipped scenarios' workspace in front of the arm,
/// inside the calibration cage's footprint (x 0.27..0.45 m, y -0.10..0.10 m) and a little
/// around it.
pub const WORKSPACE_X_M: [f64; 2] = [0.25, 0.47];
pub const WORKSPACE_Y_M: [f64; 2] = [-0.14, 0.14];

/// The scene's lighting as the renderer applies it: a face of albedo `s` and outward normal
/// `n` shows grey `s · (ambient + intensity · max(0, n·l))`.
#[derive(Debug, Clone, Copy)]
pub struct Lighting {
    pub towards_light: [f64; 3],
    pub intensity: f64,
    pub ambient: f64,
    pub table_shade: f64,
}

impl Lighting {
    /// From a scenario's `[light]` and `[table]`.
    pub fn of_scenario(toml_text: &str) -> Self {
        let doc: toml::Table = toml_text.parse().expect("scenario TOML");
        let num = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)).expect("number");
        let light = doc["light"].as_table().expect("[light]");
        let d: Vec<f64> = light["direction"].as_array().expect("direction").iter().map(num).collect();
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        Self {
            towards_light: [d[0] / len, d[1] / len, d[2] / len],
            intensity: num(&light["intensity"]),
            ambient: num(&light["ambient"]),
            table_shade: num(&doc["table"].as_table().expect("[table]")["shade"]),
        }
    }

    /// Grey level (0..1) of a face of albedo `shade` and normal `n`.
    pub fn grey(&self, shade: f64, n: [f64; 3]) -> f64 {
        let l = self.towards_light;
        (shade * (self.ambient + self.intensity * (n[0] * l[0] + n[1] * l[1] + n[2] * l[2]).max(0.0))).clamp(0.0, 1.0)
    }
}

/// Outward normals of a block's faces in the block frame, in the simulator's face order
/// (`sim/README.md`), bottom faces as `None` (never seen).
fn face_normals(kind: &str, size_mm: [f64; 3]) -> Vec<Option<[f64; 3]>> {
    let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    let neg = |v: [f64; 3]| [-v[0], -v[1], -v[2]];
    match kind {
        "cube" | "bar" => vec![Some(x), Some(neg(x)), Some(y), Some(neg(y)), Some(z), None],
        "wedge" => {
            // The slope rises from -x to +x over the whole length.
            let (l, h) = (size_mm[0], size_mm[2]);
            let n = (l * l + h * h).sqrt();
            vec![Some(neg(y)), Some(y), None, Some(x), Some([-h / n, 0.0, l / n])]
        }
        "l_block" => vec![Some(neg(y)), Some(y), None, Some(x), Some(z), Some(neg(x)), Some(z), Some(neg(x))],
        _ => panic!("unknown kind {kind}"),
    }
}

/// Random albedos for a block's faces such that, as rendered, every seen face differs by at
/// least `min_contrast` (0..1) from the table and from the block's other seen faces: the
/// design's "distinct face brightness so edges show". (The simulator's own seeded shades, a
/// shuffle of distinct albedos, do not look at the lighting: a face can render at the table's
/// grey and its outline vanish.)
fn contrasting_shades(rng: &mut SplitMix64, kind: &str, size_mm: [f64; 3], yaw_deg: f64, light: &Lighting, min_contrast: f64) -> Vec<f64> {
    let (s, c) = yaw_deg.to_radians().sin_cos();
    let normals: Vec<Option<[f64; 3]>> = face_normals(kind, size_mm).into_iter().map(|n| n.map(|n| [c * n[0] - s * n[1], s * n[0] + c * n[1], n[2]])).collect();
    let table = light.grey(light.table_shade, [0.0, 0.0, 1.0]);
    for _ in 0..100_000 {
        let shades: Vec<f64> = normals.iter().map(|_| (rng.range(0.2, 0.95) * 100.0).round() / 100.0).collect();
        let greys: Vec<f64> = normals.iter().zip(&shades).filter_map(|(n, &a)| n.map(|n| light.grey(a, n))).collect();
        let apart = greys.iter().enumerate().all(|(i, g)| (g - table).abs() >= min_contrast && greys[..i].iter().all(|h| (g - h).abs() >= min_contrast));
        if apart {
            return shades;
        }
    }
    panic!("no contrasting shades for a {kind} at yaw {yaw_deg}");
}

/// Least rendered contrast of the random layouts' faces with the table and with each other:
/// 12 grey levels of 255 (sensor noise is 1.5).
pub const MIN_CONTRAST: f64 = 12.0 / 255.0;

/// The corners of a block's bounding box (it stands on the table), robot frame.
pub fn box_corners_m(b: &BlockLayout) -> Vec<[f64; 3]> {
    let (s, c) = b.yaw_deg.to_radians().sin_cos();
    let [hx, hy, h] = [0.5e-3 * b.size_mm[0], 0.5e-3 * b.size_mm[1], 1e-3 * b.size_mm[2]];
    let mut out = Vec::with_capacity(8);
    for (x, y) in [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)] {
        for z in [0.0, h] {
            out.push([b.position_m[0] + c * x - s * y, b.position_m[1] + s * x + c * y, z]);
        }
    }
    out
}

/// Whether both cameras see the whole block, `margin_px` inside the image.
pub fn in_view(b: &BlockLayout, cameras: &[Camera; 2], width: f64, height: f64, margin_px: f64) -> bool {
    box_corners_m(b).iter().all(|x| {
        cameras.iter().all(|cam| {
            let p = cam.project(*x);
            p[0] >= margin_px && p[0] <= width - margin_px && p[1] >= margin_px && p[1] <= height - margin_px
        })
    })
}

/// A seeded layout of `count` blocks: kinds cube/bar/wedge/l_block, sides 20-60 mm, random
/// yaw and shades ([`contrasting_shades`]), footprints (their circumscribed circles plus
/// 15 mm) not overlapping, each seen whole by both cameras (`visible`: a facet ends at the
/// block's edges, and the image border is none).
pub fn random_layout(seed: u64, count: usize, light: &Lighting, visible: &dyn Fn(&BlockLayout) -> bool) -> Vec<BlockLayout> {
    const KINDS: [&str; 4] = ["cube", "bar", "wedge", "l_block"];
    // The offset keeps the layouts (and the found rates asserted over them) those of the
    // generator this test began with.
    let mut rng = SplitMix64::new(seed ^ 0x5eed_5eed_1234_abcd);
    let mut blocks: Vec<BlockLayout> = Vec::new();
    let radius = |b: &BlockLayout| 0.5e-3 * b.size_mm[0].hypot(b.size_mm[1]);
    let mut attempts = 0;
    while blocks.len() < count {
        attempts += 1;
        assert!(attempts < 10_000, "seed {seed}: cannot place {count} blocks");
        let kind = KINDS[rng.below(KINDS.len())];
        let mut size_mm = [rng.range(20.0, 60.0), rng.range(20.0, 60.0), rng.range(20.0, 60.0)].map(|s| s.round());
        if kind == "cube" {
            size_mm = [size_mm[0]; 3];
        }
        let position_m = [rng.range(WORKSPACE_X_M[0], WORKSPACE_X_M[1]), rng.range(WORKSPACE_Y_M[0], WORKSPACE_Y_M[1])];
        let yaw_deg = rng.range(-180.0, 180.0).round();
        let shades = contrasting_shades(&mut rng, kind, size_mm, yaw_deg, light, MIN_CONTRAST);
        let b = BlockLayout { kind, size_mm, position_m, yaw_deg, shades };
        let clear = blocks.iter().all(|o| {
            let d = (b.position_m[0] - o.position_m[0]).hypot(b.position_m[1] - o.position_m[1]);
            d > radius(&b) + radius(o) + 0.015
        });
        if clear && visible(&b) {
            blocks.push(b);
        }
    }
    blocks
}

/// A scenario file: `base` (a shipped scenario: its cameras, table, light, cage, arm) with
/// its blocks, task and events replaced by `blocks`, and the given `[render] antialias`.
pub fn scenario_toml(base: &str, name: &str, seed: u64, blocks: &[BlockLayout], antialias: bool) -> String {
    let mut doc: toml::Table = base.parse().expect("shipped scenario is valid TOML");
    doc.insert("name".into(), toml::Value::String(name.into()));
    doc.insert("description".into(), toml::Value::String(format!("random layout, seed {seed}")));
    doc.insert("seed".into(), toml::Value::Integer(seed as i64));
    doc.remove("events");
    // Rendered as a camera sees edges (a pixel an edge crosses takes the mixed grey), or
    // aliased for diagnosis.
    let render = doc.get_mut("render").and_then(|r| r.as_table_mut()).expect("[render]");
    render.insert("antialias".into(), toml::Value::Boolean(antialias));
    let arr: Vec<toml::Value> = blocks
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let mut t = toml::Table::new();
            t.insert("name".into(), toml::Value::String(format!("b{i}_{}", b.kind)));
            t.insert("kind".into(), toml::Value::String(b.kind.into()));
            t.insert("size_mm".into(), toml::Value::Array(b.size_mm.iter().map(|&v| toml::Value::Float(v)).collect()));
            t.insert("position_m".into(), toml::Value::Array(b.position_m.iter().map(|&v| toml::Value::Float(v)).collect()));
            t.insert("yaw_deg".into(), toml::Value::Float(b.yaw_deg));
            t.insert("shades".into(), toml::Value::Array(b.shades.iter().map(|&v| toml::Value::Float(v)).collect()));
            toml::Value::Table(t)
        })
        .collect();
    doc.insert("blocks".into(), toml::Value::Array(arr));
    let mut task = toml::Table::new();
    task.insert("target".into(), toml::Value::String(format!("b0_{}", blocks[0].kind)));
    doc.insert("task".into(), toml::Value::Table(task));
    toml::to_string(&doc).expect("serialise scenario")
}
