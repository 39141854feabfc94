//! The road networks that link units (`anchor.snap_to_lane`) and prediction models
//! (`along_roads`) of one spec use, loaded once per distinct `(scenario, network_file)` and
//! shared. A caller may put a network in beforehand (a benchmark's generated town), and it is then
//! used for those parameters instead of loading.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use kpl_core::Value;
use kpl_roads::RoadNetwork;
use kpl_roads::scenarios::{self, GridTownSize};

/// Road networks by the parameters that name them.
#[derive(Debug, Default, Clone)]
pub struct Networks {
    loaded: BTreeMap<(String, String), Arc<RoadNetwork>>,
    /// Relative `network_file` paths are read from here (the spec's directory in a run).
    base_dir: Option<PathBuf>,
}

/// The `scenario` and `network_file` parameters of a call (`network_file` empty when not set).
pub fn network_key(params: &BTreeMap<String, Value>) -> (String, String) {
    let text = |name: &str| params.get(name).and_then(Value::as_str).unwrap_or("").to_string();
    let scenario = match text("scenario") {
        s if s.is_empty() => "crossing".to_string(),
        s => s,
    };
    (scenario, text("network_file"))
}

impl Networks {
    /// Reads relative `network_file` paths from `dir` (by default: the working directory).
    pub fn with_base_dir(mut self, dir: &Path) -> Networks {
        self.base_dir = Some(dir.to_path_buf());
        self
    }

    /// Uses `network` wherever a call names `scenario` (and no network file).
    pub fn insert(&mut self, scenario: &str, network: Arc<RoadNetwork>) {
        self.loaded.insert((scenario.to_string(), String::new()), network);
    }

    /// The network a call's parameters name: its `network_file` when set, else its built-in
    /// `scenario` (default `crossing`; `grid_town` at its default size).
    pub fn resolve(&mut self, params: &BTreeMap<String, Value>) -> Result<Arc<RoadNetwork>, String> {
        let key = network_key(params);
        if let Some(network) = self.loaded.get(&key) {
            return Ok(network.clone());
        }
        let network = if key.1.is_empty() {
            let file = scenarios::by_name(&key.0, GridTownSize::default())
                .ok_or_else(|| format!("unknown road network scenario `{}`", key.0))?;
            RoadNetwork::build(&file).map_err(|e| format!("cannot build road network `{}`: {e}", key.0))?
        } else {
            let path = match &self.base_dir {
                Some(dir) => dir.join(&key.1),
                None => PathBuf::from(&key.1),
            };
            RoadNetwork::load(&path)
                .map_err(|e| format!("cannot load road network `{}`: {e}", path.display()))?
        };
        let network = Arc::new(network);
        self.loaded.insert(key, network.clone());
        Ok(network)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;

    #[test]
    fn one_network_per_parameters() {
        let mut networks = Networks::default();
        let mut params = BTreeMap::new();
        params.insert("scenario".to_string(), Value::str("bridge"));
        params.insert("network_file".to_string(), Value::str(""));
        let a = networks.resolve(&params).unwrap();
        let b = networks.resolve(&params).unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        assert!(a.road_by_name("overpass").is_some());
        params.insert("network_file".to_string(), Value::str("/nonexistent/roads.json"));
        assert!(networks.resolve(&params).unwrap_err().contains("/nonexistent/roads.json"));
    }
}
