//! CATER's object classes and names: the class `size_color_shape_material`, OPNet's class indices
//! (the 193 classes its detector and perception pickles use, `object_indices.py`), and the Blender
//! instance names CATER gives objects (`Cone_1`, `SmoothCylinder-Short_0`, `Spl_0`).
//!
//! OPNet's index table is sorted by size (large, medium, small), then material (metal, rubber), then
//! `color_shape` alphabetically, the snitch (`small_gold_spl_metal`, 140) falling among the small
//! metal classes. It is built here by that rule; the tests check it against indices OPNet's code
//! names (the snitch's 140, the large cones `0, 4, .., 60` of its `LARGE_CONS_INDICES`).

use std::sync::OnceLock;

/// CATER's sizes, in OPNet's order, with the scale CATER gives Blender (`properties.json`).
pub const SIZES: [(&str, f64); 3] = [("large", 0.75), ("medium", 0.5), ("small", 0.25)];
/// The snitch's scale ("slightly larger than small").
pub const SNITCH_SCALE: f64 = 0.3;
pub const COLORS: [&str; 8] = ["blue", "brown", "cyan", "gray", "green", "purple", "red", "yellow"];
pub const MATERIALS: [&str; 2] = ["metal", "rubber"];
/// The shapes a CATER object other than the snitch can have.
pub const SHAPES: [&str; 4] = ["cone", "cube", "cylinder", "sphere"];

/// The snitch's class.
pub const SNITCH_CLASS: &str = "small_gold_spl_metal";
/// The snitch's OPNet class index.
pub const SNITCH_INDEX: u32 = 140;

/// OPNet's class names, by index.
pub fn opnet_classes() -> &'static [String] {
    static TABLE: OnceLock<Vec<String>> = OnceLock::new();
    TABLE.get_or_init(|| {
        let mut table = Vec::with_capacity(193);
        for (size, _) in SIZES {
            for material in MATERIALS {
                let mut group: Vec<(String, String)> = COLORS
                    .iter()
                    .flat_map(|c| SHAPES.iter().map(move |s| ((*c).to_owned(), (*s).to_owned())))
                    .collect();
                if size == "small" && material == "metal" {
                    group.push(("gold".into(), "spl".into()));
                }
                group.sort();
                table.extend(group.into_iter().map(|(c, s)| format!("{size}_{c}_{s}_{material}")));
            }
        }
        table
    })
}

/// A class's OPNet index.
pub fn opnet_index(class: &str) -> Option<u32> {
    opnet_classes().iter().position(|c| c == class).and_then(|i| u32::try_from(i).ok())
}

/// The class of an OPNet index.
pub fn opnet_class(index: i64) -> Option<&'static str> {
    usize::try_from(index).ok().and_then(|i| opnet_classes().get(i)).map(String::as_str)
}

/// A class's parts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClassParts<'a> {
    pub size: &'a str,
    pub color: &'a str,
    pub shape: &'a str,
    pub material: &'a str,
}

/// Splits `size_color_shape_material`; `None` unless it has exactly four parts.
pub fn parse_class(class: &str) -> Option<ClassParts<'_>> {
    let mut parts = class.split('_');
    let out = ClassParts {
        size: parts.next()?,
        color: parts.next()?,
        shape: parts.next()?,
        material: parts.next()?,
    };
    parts.next().is_none().then_some(out)
}

/// The shape of a class (`cone` for `large_red_cone_rubber`), or the class itself if it is not of
/// the four-part form.
pub fn shape_of(class: &str) -> &str {
    parse_class(class).map_or(class, |p| p.shape)
}

/// Whether a class is a cone, the only shape that contains (OPNet's `is_cone_object`).
pub fn is_cone(class: &str) -> bool {
    shape_of(class) == "cone"
}

/// OPNet's `LARGE_CONS_INDICES` test: a large cone (its heuristic shifts the snitch's box down for
/// these).
pub fn is_large_cone(class: &str) -> bool {
    parse_class(class).is_some_and(|p| p.size == "large" && p.shape == "cone")
}

/// The Blender object CATER loads for a shape (`properties.json`; the snitch is `Spl`).
pub fn blender_name(shape: &str) -> &'static str {
    match shape {
        "cube" => "SmoothCube_v2",
        "sphere" => "Sphere",
        "cylinder" => "SmoothCylinder-Short",
        "cone" => "Cone",
        _ => "Spl",
    }
}

/// The instance name CATER's `add_object` gives the `count`-th object of a shape: `Cone_1`.
pub fn instance_name(shape: &str, count: usize) -> String {
    format!("{}_{count}", blender_name(shape))
}

/// Whether an instance name is a cone's (OPNet's scripts test `"Cone" in name`).
pub fn is_cone_instance(instance: &str) -> bool {
    instance.contains("Cone")
}
