//! The robot model: the URDF chain (k) with the tool from `tool.toml` and the joint limits from
//! the URDF and `servos.toml`; forward kinematics through k.
use std::path::Path;
use std::sync::Mutex;

use nalgebra::{DMatrix, Isometry3, Vector3};

use super::calibration::{FileText, Servos, Tool};
use super::error::RobotError;
use super::planar::Planar;

/// One actuated joint: its name, servo and limits (the intersection of the URDF limits, the
/// optional `joint_limits` of servos.toml and the servo's degree range).
#[derive(Debug, Clone, PartialEq)]
pub struct JointSpec {
    /// URDF joint name.
    pub name: String,
    /// Bus id of the servo driving it.
    pub servo_id: u8,
    /// Lower position limit, rad.
    pub lower: f64,
    /// Upper position limit, rad.
    pub upper: f64,
    /// Velocity limit, rad/s.
    pub velocity: f64,
    /// Acceleration limit, rad/s^2.
    pub acceleration: f64,
    /// Jerk limit, rad/s^3.
    pub jerk: f64,
}

/// Tool tip position and tool axis (unit, shank to tip) in the robot base frame, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolPose {
    /// Tool tip, metres.
    pub position: Vector3<f64>,
    /// Tool axis, unit vector.
    pub axis: Vector3<f64>,
}

/// The arm: k's chain from the URDF (tool joint set from `tool.toml`) and its calibration.
pub struct Robot {
    chain: Mutex<k::SerialChain<f64>>,
    /// Actuated joints, base to tip.
    pub joints: Vec<JointSpec>,
    /// The tool.
    pub tool: Tool,
    /// The servo calibration.
    pub servos: Servos,
    /// Closed-form IK parameters, when the chain has the DOFBOT structure.
    pub(crate) planar: Option<Planar>,
}

impl std::fmt::Debug for Robot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Robot")
            .field("joints", &self.joints)
            .field("tool", &self.tool)
            .finish()
    }
}

impl Robot {
    /// Builds the model from a URDF file, `tool.toml` and `servos.toml`.
    pub fn load(urdf: &Path, tool: &Path, servos: &Path) -> Result<Self, RobotError> {
        Self::with_tool(urdf, Tool::load(tool)?, servos)
    }

    /// [`Robot::load`] with the tool given (held in memory) instead of read from a file.
    pub fn with_tool(urdf: &Path, tool_cfg: Tool, servos: &Path) -> Result<Self, RobotError> {
        let servos = FileText::read(servos)?;
        Self::from_texts(&FileText::read(urdf)?, tool_cfg, &servos)
    }

    /// [`Robot::with_tool`] from the URDF and servos.toml held in memory (their paths named in
    /// errors).
    pub fn from_texts(urdf: &FileText, tool: Tool, servos: &FileText) -> Result<Self, RobotError> {
        let servos_cfg = Servos::parse(&servos.path, &servos.text)?;
        let description = urdf_rs::read_from_string(&urdf.text).map_err(|e| RobotError::Io {
            file: urdf.path.clone(),
            message: e.to_string(),
        })?;
        Self::from_parts(description, &urdf.path, tool, servos_cfg, &servos.path)
    }

    /// Builds the model from a parsed URDF; `urdf_file` and `servos_file` only name the files in
    /// error messages.
    pub fn from_parts(
        mut description: urdf_rs::Robot,
        urdf_file: &Path,
        tool: Tool,
        servos: Servos,
        servos_file: &Path,
    ) -> Result<Self, RobotError> {
        let tool_joint = description
            .joints
            .iter_mut()
            .find(|j| j.name == tool.joint)
            .ok_or_else(|| {
                RobotError::bad(
                    urdf_file,
                    format!("joint {}", tool.joint),
                    "tool joint not found",
                )
            })?;
        if !matches!(tool_joint.joint_type, urdf_rs::JointType::Fixed) {
            return Err(RobotError::bad(
                urdf_file,
                format!("joint {}", tool.joint),
                "must be fixed",
            ));
        }
        tool_joint.origin.xyz = urdf_rs::Vec3(tool.tip_offset);
        let tool_child = tool_joint.child.link.clone();
        if description
            .joints
            .iter()
            .any(|j| j.parent.link == tool_child)
        {
            return Err(RobotError::bad(
                urdf_file,
                format!("joint {}", tool.joint),
                "must end the chain",
            ));
        }
        check_joints(&description, urdf_file)?;
        let whole = k::Chain::<f64>::from(&description);
        let end = whole
            .find(&tool.joint)
            .ok_or_else(|| RobotError::bad(urdf_file, "robot", "tool joint not in the chain"))?;
        let chain = k::SerialChain::from_end(end);

        let mut joints = Vec::new();
        for node in chain.iter() {
            let joint = node.joint();
            if matches!(joint.joint_type, k::JointType::Fixed) {
                continue;
            }
            let name = joint.name.clone();
            if !matches!(joint.joint_type, k::JointType::Rotational { .. }) {
                return Err(RobotError::bad(
                    urdf_file,
                    format!("joint {name}"),
                    "the arm's joints must be revolute (each is a servo that turns)",
                ));
            }
            let urdf_limit = joint.limits.as_ref().map(|r| [r.min, r.max]);
            drop(joint);
            let urdf_velocity = description
                .joints
                .iter()
                .find(|j| j.name == name)
                .map(|j| j.limit.velocity);
            joints.push(joint_spec(
                &name,
                UrdfLimits {
                    position: urdf_limit,
                    velocity: urdf_velocity,
                },
                &servos,
                urdf_file,
                servos_file,
            )?);
        }
        let mut robot = Robot {
            chain: Mutex::new(chain),
            joints,
            tool,
            servos,
            planar: None,
        };
        robot.planar = robot.planar_geometry();
        Ok(robot)
    }

    /// The closed-form IK parameters, when the chain has five joints in the DOFBOT structure.
    fn planar_geometry(&self) -> Option<Planar> {
        if self.dof() != 5 {
            return None;
        }
        let zero = [0.0; 5];
        let (frames, axes) = self.joint_frames(&zero);
        let tool = self.fk(&zero);
        Planar::from_zero_pose(&frames, &axes, tool.position, tool.axis)
    }

    /// Number of actuated joints.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    /// True when IK uses the closed form (the chain has the DOFBOT structure).
    pub fn has_closed_form(&self) -> bool {
        self.planar.is_some()
    }

    /// Transform of the tool link (tip at its origin) in the base frame, through k.
    pub fn fk_isometry(&self, q: &[f64]) -> Isometry3<f64> {
        let chain = self.chain.lock().unwrap_or_else(|e| e.into_inner());
        chain.set_joint_positions_unchecked(q);
        chain.end_transform()
    }

    /// Tool tip and tool axis in the base frame for joint angles `q`, through k.
    pub fn fk(&self, q: &[f64]) -> ToolPose {
        let iso = self.fk_isometry(q);
        ToolPose {
            position: iso.translation.vector,
            axis: iso.rotation * Vector3::from(self.tool.axis),
        }
    }

    /// World transforms of the actuated joints' frames at `q` (axes: [`Robot::joint_axes`]).
    pub(crate) fn joint_frames(&self, q: &[f64]) -> (Vec<Isometry3<f64>>, Vec<Vector3<f64>>) {
        let chain = self.chain.lock().unwrap_or_else(|e| e.into_inner());
        chain.set_joint_positions_unchecked(q);
        chain.update_transforms();
        let mut frames = Vec::new();
        let mut axes = Vec::new();
        for node in chain.iter() {
            let joint = node.joint();
            if let k::JointType::Rotational { axis } = &joint.joint_type {
                let t = joint.world_transform().unwrap_or_else(Isometry3::identity);
                axes.push(t.rotation * axis.into_inner());
                frames.push(t);
            }
        }
        (frames, axes)
    }

    /// 6 x dof Jacobian of the tool tip (linear rows first, then angular) at `q`, through k.
    pub fn jacobian(&self, q: &[f64]) -> DMatrix<f64> {
        let chain = self.chain.lock().unwrap_or_else(|e| e.into_inner());
        chain.set_joint_positions_unchecked(q);
        chain.update_transforms();
        k::jacobian(&chain)
    }

    /// Runs `f` on k's serial chain (for k's own solvers).
    pub(crate) fn with_chain<R>(&self, f: impl FnOnce(&k::SerialChain<f64>) -> R) -> R {
        let chain = self.chain.lock().unwrap_or_else(|e| e.into_inner());
        f(&chain)
    }

    /// Index of the first joint outside its limits (by more than `tol`), if any.
    pub fn limit_violation(&self, q: &[f64], tol: f64) -> Option<usize> {
        self.joints
            .iter()
            .zip(q)
            .position(|(j, v)| *v < j.lower - tol || *v > j.upper + tol)
    }
}

/// What the URDF says of one actuated joint: its position limits and its `<limit velocity>`.
struct UrdfLimits {
    /// `[lower, upper]`, rad (none without a `<limit>`).
    position: Option<[f64; 2]>,
    /// `<limit velocity>`, rad/s (none when the joint is not in the description).
    velocity: Option<f64>,
}

/// The joint's limits: positions the intersection of the URDF's, the servo's degree range and
/// servos.toml `joint_limits`; velocity the smaller of servos.toml `velocity` and the URDF's
/// `<limit velocity>` (refused unless finite and above 0).
fn joint_spec(
    name: &str,
    urdf: UrdfLimits,
    servos: &Servos,
    urdf_file: &Path,
    servos_file: &Path,
) -> Result<JointSpec, RobotError> {
    let servo = servos.for_joint(name).ok_or_else(|| {
        RobotError::bad(
            servos_file,
            "servo",
            format!("no servo for URDF joint {name}"),
        )
    })?;
    let [a, b] = urdf.position.ok_or_else(|| {
        RobotError::bad(urdf_file, format!("joint {name}"), "needs position limits")
    })?;
    let urdf_velocity = match urdf.velocity {
        Some(v) if !(v.is_finite() && v > 0.0) => {
            let msg = format!("<limit velocity=\"{v}\"> must be finite and above 0 rad/s");
            return Err(RobotError::bad(urdf_file, format!("joint {name}"), msg));
        }
        Some(v) => v,
        None => f64::INFINITY,
    };
    let [sa, sb] = servo.joint_range();
    let [ca, cb] = servo
        .joint_limits
        .unwrap_or([f64::NEG_INFINITY, f64::INFINITY]);
    let (lower, upper) = (a.max(sa).max(ca), b.min(sb).min(cb));
    if !super::calibration::less(lower, upper) {
        let msg = format!("joint {name}: URDF limits, servo range and joint_limits do not overlap");
        return Err(RobotError::bad(
            servos_file,
            format!("servo id {}", servo.id),
            msg,
        ));
    }
    Ok(JointSpec {
        name: name.to_string(),
        servo_id: servo.id,
        lower,
        upper,
        velocity: servo.velocity.unwrap_or(0.0).min(urdf_velocity),
        acceleration: servo.acceleration.unwrap_or(0.0),
        jerk: servo.jerk.unwrap_or(0.0),
    })
}

/// Refuses a URDF whose joints the kinematics cannot take (the `k` crate panics on a range
/// whose lower limit exceeds its upper): per joint, a finite origin, a finite non-zero axis
/// for a moving joint, and finite limits with lower <= upper for a revolute or prismatic
/// one; each refusal names the file and the joint.
fn check_joints(description: &urdf_rs::Robot, urdf_file: &Path) -> Result<(), RobotError> {
    for j in &description.joints {
        let bad = |what: &str| RobotError::bad(urdf_file, format!("joint {}", j.name), what);
        let origin = j.origin.xyz.0.iter().chain(&j.origin.rpy.0);
        if !origin.into_iter().all(|v| v.is_finite()) {
            return Err(bad("origin xyz/rpy must be finite"));
        }
        if matches!(j.joint_type, urdf_rs::JointType::Fixed) {
            continue;
        }
        let axis = j.axis.xyz.0;
        if !axis.iter().all(|v| v.is_finite()) || axis.iter().all(|v| *v == 0.0) {
            return Err(bad("axis must be finite and not zero"));
        }
        let limited = matches!(
            j.joint_type,
            urdf_rs::JointType::Revolute | urdf_rs::JointType::Prismatic
        );
        let (lo, hi) = (j.limit.lower, j.limit.upper);
        if limited && !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(bad(&format!(
                "limit lower {lo} and upper {hi} must be finite with lower <= upper"
            )));
        }
    }
    Ok(())
}
