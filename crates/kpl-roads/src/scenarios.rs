//! Built-in road networks: `crossing` (one four-way crossing), `bridge` (a road passing under a
//! bridge that carries another road) and `grid_town` (a generated grid of streets for scale tests).
//! Each is returned in file form, so it can be saved as JSON, edited and loaded back.

use crate::format::{NetworkFile, OccluderKind, OccluderSpec};

/// The names [`by_name`] knows.
pub const NAMES: [&str; 3] = ["crossing", "bridge", "grid_town"];

/// Length of the hidden stretch in the `bridge` scenario: two seconds at the 13.9 m/s speed limit.
pub const BRIDGE_LENGTH_M: f64 = 27.8;

/// The size of a generated grid town.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridTownSize {
    /// Blocks from west to east.
    pub blocks_x: u32,
    /// Blocks from south to north.
    pub blocks_y: u32,
    /// Side of a block (distance between neighbouring crossings), in metres.
    pub block_m: f64,
}

impl Default for GridTownSize {
    /// 10 x 10 blocks of 100 m.
    fn default() -> GridTownSize {
        GridTownSize { blocks_x: 10, blocks_y: 10, block_m: 100.0 }
    }
}

impl GridTownSize {
    /// A square town of 100 m blocks with room for `n_cars` at about 11 cars per block (one car
    /// per 36 m of lane, a busy town; at least 2 x 2 blocks). Used by the scale benchmarks.
    pub fn for_cars(n_cars: u32) -> GridTownSize {
        let blocks = ((f64::from(n_cars) / 11.0).sqrt().round() as u32).clamp(2, 200);
        GridTownSize { blocks_x: blocks, blocks_y: blocks, block_m: 100.0 }
    }
}

/// The built-in network called `name`; `grid` sizes `grid_town` and is ignored otherwise.
pub fn by_name(name: &str, grid: GridTownSize) -> Option<NetworkFile> {
    match name {
        "crossing" => Some(crossing()),
        "bridge" => Some(bridge()),
        "grid_town" => Some(grid_town(grid)),
        _ => None,
    }
}

/// A four-way crossing at the origin with 150 m arms (`west`, `east`, `south`, `north`), one
/// 3.5 m lane each way, 50 km/h.
pub fn crossing() -> NetworkFile {
    let mut file = NetworkFile::new();
    file.add_node("c", [0.0, 0.0]);
    file.add_node("w", [-150.0, 0.0]);
    file.add_node("e", [150.0, 0.0]);
    file.add_node("s", [0.0, -150.0]);
    file.add_node("n", [0.0, 150.0]);
    file.add_road("west", "w", "c", Vec::new());
    file.add_road("east", "c", "e", Vec::new());
    file.add_road("south", "s", "c", Vec::new());
    file.add_road("north", "c", "n", Vec::new());
    file
}

/// A 400 m road `main` from west to east passing at x = 0 under a bridge that carries the road
/// `overpass` (south to north, level 1). The bridge hides 27.8 m of `main`, about two seconds of
/// driving at the speed limit.
pub fn bridge() -> NetworkFile {
    let mut file = NetworkFile::new();
    file.add_node("w", [-200.0, 0.0]);
    file.add_node("e", [200.0, 0.0]);
    file.add_node("s", [0.0, -150.0]);
    file.add_node("n", [0.0, 150.0]);
    file.add_road("main", "w", "e", Vec::new());
    file.add_road("overpass", "s", "n", Vec::new());
    if let Some(overpass) = file.roads.last_mut() {
        overpass.level = 1;
    }
    file.occluders.push(OccluderSpec::stretch(
        "bridge",
        OccluderKind::Bridge,
        "main",
        200.0 - BRIDGE_LENGTH_M / 2.0,
        200.0 + BRIDGE_LENGTH_M / 2.0,
    ));
    file
}

/// A grid of streets: crossings every `block_m` metres, `blocks_x` by `blocks_y` blocks, and a
/// short road leaving the town from every crossing on the edge (where cars enter and leave).
/// Crossing `x{i}y{j}` is at `(i * block_m, j * block_m)`.
pub fn grid_town(size: GridTownSize) -> NetworkFile {
    let GridTownSize { blocks_x, blocks_y, block_m } = size;
    let stub_m = (block_m / 2.0).max(30.0);
    let name = |i: u32, j: u32| format!("x{i}y{j}");
    let mut file = NetworkFile::new();
    for j in 0..=blocks_y {
        for i in 0..=blocks_x {
            file.add_node(&name(i, j), [f64::from(i) * block_m, f64::from(j) * block_m]);
        }
    }
    for j in 0..=blocks_y {
        for i in 0..=blocks_x {
            if i < blocks_x {
                file.add_road(&format!("h{i}_{j}"), &name(i, j), &name(i + 1, j), Vec::new());
            }
            if j < blocks_y {
                file.add_road(&format!("v{i}_{j}"), &name(i, j), &name(i, j + 1), Vec::new());
            }
        }
    }
    // Roads out of town: west and east ends of every row, south and north ends of every column.
    let (x_max, y_max) = (f64::from(blocks_x) * block_m, f64::from(blocks_y) * block_m);
    for j in 0..=blocks_y {
        let y = f64::from(j) * block_m;
        file.add_node(&format!("out_w{j}"), [-stub_m, y]);
        file.add_node(&format!("out_e{j}"), [x_max + stub_m, y]);
        file.add_road(&format!("in_w{j}"), &format!("out_w{j}"), &name(0, j), Vec::new());
        file.add_road(&format!("in_e{j}"), &name(blocks_x, j), &format!("out_e{j}"), Vec::new());
    }
    for i in 0..=blocks_x {
        let x = f64::from(i) * block_m;
        file.add_node(&format!("out_s{i}"), [x, -stub_m]);
        file.add_node(&format!("out_n{i}"), [x, y_max + stub_m]);
        file.add_road(&format!("in_s{i}"), &format!("out_s{i}"), &name(i, 0), Vec::new());
        file.add_road(&format!("in_n{i}"), &name(i, blocks_y), &format!("out_n{i}"), Vec::new());
    }
    file
}
