//! The compliant grinding tool of `tool.toml`'s `[removal]` table: spring, preload, contact
//! pressure (Hertz or a measured radial table), spindle speed, the least spindle tilt the
//! planner holds and Preston's coefficient.
//! Method and the defaults' sources: docs/ALGORITHMS.md, "Removal planning".
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::robot::error::parse_toml;
use crate::robot::{Robot, RobotError, ToolText};

/// The removal model of the tool (units in the key names: N, mm, MPa, rpm, degrees).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ToolModel {
    /// Spring rate of the compliant mount (or the abrasive), N/mm: force = rate x penetration.
    pub spring_rate_n_mm: f64,
    /// Commanded preload: how far the ball centre is commanded below touching, mm.
    pub preload_mm: f64,
    /// Effective contact modulus E* of the compliant abrasive against the (far stiffer) part,
    /// MPa: the Hertz contact of a ball of the tool's radius.
    pub modulus_mpa: f64,
    /// Measured radial pressure profile instead of Hertz: `[[r_mm, relative pressure], ..]`
    /// with r increasing from 0; the pressure is scaled so that it integrates to the force.
    pub influence_table: Option<Vec<[f64; 2]>>,
    /// Spindle speed, revolutions per minute.
    pub spindle_rpm: f64,
    /// Smallest angle between the spindle axis and the surface normal that the planner holds
    /// where the arm can, degrees: a ball spinning about the normal does not cut at its pole
    /// (the relative speed at the contact is omega x R x sin(tilt)), and near it the removal
    /// follows the axis error by cot(tilt). The removal model itself takes the axis the arm
    /// holds at each contact (`Contact::spin`), not this value.
    pub tilt_deg: f64,
    /// Preston coefficient k, mm^2/N (removal depth rate = k x pressure x relative speed).
    pub preston_k_mm2_n: f64,
    /// Relative standard uncertainty of k (0.3 = 30 %).
    pub preston_k_rel_sd: f64,
    /// The direction in which the compliant mount gives (default
    /// [`ComplianceDirection::SurfaceNormal`], the model of files written before the key).
    pub compliance_direction: ComplianceDirection,
    /// Standard deviation of where the patch lands about where the model puts it, mm, along
    /// each direction of the surface (default 0): the removal model spreads each contact's
    /// influence by it ([`super::Influence::placed_rate`]). Measured for the shipped spindle on
    /// the simulated cell: 0.11 mm median and 0.26 mm p90 per piece of stroke between the
    /// planner's pressed contact and the simulator's (docs/ALGORITHMS.md, "Where a spindle's
    /// patch lands"). Written only where set, so that a plan made without it records its tool
    /// as before.
    #[serde(skip_serializing_if = "is_zero")]
    pub placement_sd_mm: f64,
    /// The worst tool-tip error `calibrate verify` measured on this cell, mm (it writes this
    /// key into the tool.toml of its `--out`): the Monte Carlo's tip error
    /// (`montecarlo::tip_error`). Absent: the cell has no such record and the Monte Carlo
    /// takes `[monte_carlo] tip_error_mm`, saying so in plan.json.
    pub verified_tip_error_mm: Option<f64>,
}

/// Defaults: each value's source is in `calibration/tool.toml` and docs/ALGORITHMS.md.
impl Default for ToolModel {
    fn default() -> Self {
        ToolModel {
            spring_rate_n_mm: 1.0,
            preload_mm: 2.0,
            modulus_mpa: 20.0,
            influence_table: None,
            spindle_rpm: 10_000.0,
            tilt_deg: 20.0,
            preston_k_mm2_n: 5e-6,
            preston_k_rel_sd: 0.3,
            compliance_direction: ComplianceDirection::SurfaceNormal,
            placement_sd_mm: 0.0,
            verified_tip_error_mm: None,
        }
    }
}

/// The direction in which the compliant mount gives (tool.toml `[removal]
/// compliance_direction`). Method: docs/ALGORITHMS.md, "The mount's direction".
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ComplianceDirection {
    /// The ball centre gives along the surface normal: the force is the spring rate times the
    /// normal depth and the patch lies under the commanded centre (an abrasive that is itself
    /// the spring, or an ideal normal-following mount). The default for files that do not say.
    #[default]
    SurfaceNormal,
    /// The ball centre gives along the spindle axis (a spring-loaded spindle or axial-float
    /// holder): tilted by theta from the normal, the spring compresses depth / cos(theta), the
    /// normal force is rate x depth / cos^2(theta) and the patch slides depth x tan(theta)
    /// back toward the shank.
    SpindleAxis,
}

/// Whether a value is exactly zero (serde's `skip_serializing_if`).
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// Largest tool-tip error a record may hold, mm (50, as `[monte_carlo] tip_error_mm`): the
/// DOFBOT reaches about 400 mm; a value in micrometres or a typo is caught.
pub const MAX_TIP_ERROR_MM: f64 = 50.0;

/// Accepted ranges per key (inclusive, the lower end excluded where the name says `(`): wide
/// around physical tools, narrow enough that a typo (a rate in N/m, a speed in rad/s of 0)
/// is caught. k: the shipped tool's 5e-6 mm^2/N; above 1e-2 one pass at the slowest feed
/// would remove metres (k = 1 planned "0 passes" with a self-contradicting reason).
/// `placement_sd_mm` up to 2 mm: a tool that lands farther off than that misses the 2-4 mm
/// defects it is planned for.
const RANGES: [(&str, f64, f64, &str); 8] = [
    ("spring_rate_n_mm", 1e-3, 1e3, "N/mm"),
    ("preload_mm", 1e-3, 10.0, "mm"),
    ("modulus_mpa", 1e-2, 1e6, "MPa"),
    ("spindle_rpm", 1.0, 100_000.0, "rpm"),
    ("tilt_deg", 1.0, 80.0, "deg"),
    ("preston_k_mm2_n", 1e-12, 1e-2, "mm^2/N"),
    ("preston_k_rel_sd", 0.0, 1.0, ""),
    ("placement_sd_mm", 0.0, 2.0, "mm"),
];

#[derive(Deserialize)]
struct ToolFile {
    #[serde(default)]
    removal: Option<toml::Value>,
}

impl ToolModel {
    /// The one reader of tool.toml's `[removal]` table (`None`: absent, the defaults), typed
    /// and checked. `Err((place, message))`: `[removal]` when the table does not parse, else
    /// the key (`removal.KEY`).
    pub fn from_table(table: Option<&toml::Value>) -> Result<Self, (String, String)> {
        let model = match table {
            None => ToolModel::default(),
            Some(v) => v
                .clone()
                .try_into()
                .map_err(|e: toml::de::Error| ("[removal]".to_string(), e.message().to_string()))?,
        };
        model.check()?;
        Ok(model)
    }

    /// Reads the `[removal]` table of `file` (tool.toml); absent: the defaults.
    pub fn load(file: &Path) -> Result<Self, RobotError> {
        Self::of_text(&ToolText::read(file)?)
    }

    /// Reads the `[removal]` table of a tool file held in memory; absent: the defaults.
    pub fn of_text(tool: &ToolText) -> Result<Self, RobotError> {
        let parsed: ToolFile = parse_toml(&tool.path, &tool.text)?;
        Self::from_table(parsed.removal.as_ref())
            .map_err(|(key, msg)| RobotError::bad(&tool.path, key, msg))
    }

    /// The tool of a loaded robot (its tool.toml's `[removal]` table, kept by
    /// `robot::calibration` unparsed); the message names `tool.toml` and the key.
    pub fn of_robot(robot: &Robot) -> Result<Self, String> {
        Self::from_table(robot.tool.removal.as_ref()).map_err(|(key, msg)| {
            if key.starts_with('[') {
                format!("tool.toml {key}: {msg}")
            } else {
                format!("tool.toml `{key}`: {msg}")
            }
        })
    }

    /// Checks every value: `Err((key, message))` names the key as `removal.KEY`.
    pub fn check(&self) -> Result<(), (String, String)> {
        let values = [
            self.spring_rate_n_mm,
            self.preload_mm,
            self.modulus_mpa,
            self.spindle_rpm,
            self.tilt_deg,
            self.preston_k_mm2_n,
            self.preston_k_rel_sd,
            self.placement_sd_mm,
        ];
        if let Some((name, msg)) = out_of_range(&RANGES, &values) {
            return Err((format!("removal.{name}"), msg));
        }
        if let Some(e) = self.verified_tip_error_mm {
            if !(0.0..=MAX_TIP_ERROR_MM).contains(&e) {
                let msg = format!("{e:?} is outside 0..={MAX_TIP_ERROR_MM} mm");
                return Err(("removal.verified_tip_error_mm".to_string(), msg));
            }
        }
        if let Some(table) = &self.influence_table {
            check_table(table).map_err(|m| ("removal.influence_table".to_string(), m))?;
        }
        Ok(())
    }

    /// Contact force, N.
    pub fn force_n(&self) -> f64 {
        self.spring_rate_n_mm * self.preload_mm
    }

    /// The force of a ball pressed `penetration_mm` into the part as a share of the preload's
    /// (`spring_rate x penetration` over `force_n`; 0 once the ball is off the part).
    pub fn force_ratio(&self, penetration_mm: f64) -> f64 {
        penetration_mm.max(0.0) / self.preload_mm
    }

    /// Spindle angular speed, rad/s.
    pub fn omega(&self) -> f64 {
        self.spindle_rpm * std::f64::consts::TAU / 60.0
    }
}

/// A radial table: at least two rows, radii from 0 strictly increasing, pressures finite,
/// non-negative and not all zero.
fn check_table(table: &[[f64; 2]]) -> Result<(), String> {
    if table.len() < 2 {
        return Err("needs at least two rows [r_mm, pressure]".into());
    }
    if table[0][0] != 0.0 {
        return Err(format!(
            "row 1: the first radius must be 0, not {}",
            table[0][0]
        ));
    }
    for (i, row) in table.iter().enumerate() {
        if !(row[0].is_finite() && row[1].is_finite() && row[1] >= 0.0) {
            return Err(format!(
                "row {}: values must be finite, pressure >= 0",
                i + 1
            ));
        }
        if i > 0 && row[0] <= table[i - 1][0] {
            return Err(format!("row {}: radii must increase", i + 1));
        }
    }
    if table.iter().all(|r| r[1] == 0.0) {
        return Err("every pressure is zero".into());
    }
    Ok(())
}

/// The first value outside its `(name, low, high, unit)` range (inclusive; NaN is outside):
/// its name and a message with the value, the range and the unit.
pub(super) fn out_of_range(
    ranges: &[(&str, f64, f64, &str)],
    values: &[f64],
) -> Option<(String, String)> {
    ranges
        .iter()
        .zip(values)
        .find(|((_, lo, hi, _), v)| !(v.is_finite() && (*lo..=*hi).contains(*v)))
        .map(|((name, lo, hi, unit), v)| {
            (
                name.to_string(),
                format!("{v:?} is outside {lo:?}..={hi:?} {unit}"),
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load_text(text: &str) -> Result<ToolModel, String> {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("tool.toml");
        std::fs::write(&file, text).unwrap();
        ToolModel::load(&file).map_err(|e| e.to_string())
    }

    #[test]
    fn bad_values_name_the_key_on_one_line() {
        for (text, key) in [
            (
                "[removal]\nspring_rate_n_mm = -2.0\n",
                "removal.spring_rate_n_mm",
            ),
            ("[removal]\nspindle_rpm = 0.0\n", "removal.spindle_rpm"),
            (
                "[removal]\npreston_k_mm2_n = nan\n",
                "removal.preston_k_mm2_n",
            ),
            (
                "[removal]\ninfluence_table = [[0.5, 1.0], [1.0, 0.0]]\n",
                "removal.influence_table",
            ),
            (
                "[removal]\nplacement_sd_mm = -0.1\n",
                "removal.placement_sd_mm",
            ),
            (
                "[removal]\nplacement_sd_mm = nan\n",
                "removal.placement_sd_mm",
            ),
            (
                "[removal]\nplacement_sd_mm = 3.0\n",
                "removal.placement_sd_mm",
            ),
        ] {
            let e = load_text(text).unwrap_err();
            assert!(e.contains(key) && e.contains("tool.toml"), "{e}");
            assert_eq!(e.lines().count(), 1, "{e}");
        }
        let e = load_text("[removal]\nverified_tip_error_mm = -0.1\n").unwrap_err();
        assert!(e.contains("removal.verified_tip_error_mm"), "{e}");
        let m = load_text("[removal]\nverified_tip_error_mm = 0.3\n").unwrap();
        assert_eq!(m.verified_tip_error_mm, Some(0.3));
        let m = load_text("[removal]\nplacement_sd_mm = 0.08\n").unwrap();
        assert_eq!(m.placement_sd_mm, 0.08);
        let e = load_text("[removal]\nspring_rate = 2.0\n").unwrap_err();
        assert!(e.contains("spring_rate") && e.contains("[removal]"), "{e}");
    }

    #[test]
    fn absent_table_is_the_defaults_and_the_shipped_file_loads() {
        assert_eq!(load_text("joint = \"x\"\n").unwrap(), ToolModel::default());
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/tool.toml");
        let m = ToolModel::load(&shipped).unwrap();
        // the shipped tool states its spring-loaded spindle; files that do not say keep the
        // normal mount
        assert_eq!(m.compliance_direction, ComplianceDirection::SpindleAxis);
        assert_eq!(
            ToolModel {
                compliance_direction: ComplianceDirection::SurfaceNormal,
                ..m.clone()
            },
            ToolModel::default(),
            "tool.toml and the code's defaults agree"
        );
        assert!((m.force_n() - 2.0).abs() < 1e-12);
    }
}
