//! The ROS messages a recording's frames and poses come from, decoded from ROS 1 or CDR bytes.

pub mod cloud;
pub mod cursor;
pub mod point_time;
pub mod pose;

pub use cloud::Cloud;
pub use cursor::{Cursor, DecodeError, Header, Wire};
pub use point_time::{PointTimeChoice, PointTimeConvention, RawTimes, TimeOrigin, TimeUnit};
pub use pose::PoseMessage;

/// The message types read here.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kind {
    /// `sensor_msgs/PointCloud2`.
    PointCloud2,
    /// `livox_ros_driver/CustomMsg` or `livox_ros_driver2/CustomMsg`.
    LivoxCustom,
    /// `nav_msgs/Odometry`.
    Odometry,
    /// `geometry_msgs/PoseStamped`.
    PoseStamped,
    /// `geometry_msgs/PoseWithCovarianceStamped`.
    PoseWithCovarianceStamped,
    /// `tf2_msgs/TFMessage` (`/tf`, `/tf_static`).
    Tf,
}

impl Kind {
    /// The kind of a ROS type name, in ROS 1 (`pkg/Name`) or ROS 2 (`pkg/msg/Name`) spelling.
    pub fn of(type_name: &str) -> Option<Kind> {
        let name = type_name.replace("/msg/", "/");
        Some(match name.as_str() {
            "sensor_msgs/PointCloud2" => Kind::PointCloud2,
            "livox_ros_driver/CustomMsg" | "livox_ros_driver2/CustomMsg" => Kind::LivoxCustom,
            "nav_msgs/Odometry" => Kind::Odometry,
            "geometry_msgs/PoseStamped" => Kind::PoseStamped,
            "geometry_msgs/PoseWithCovarianceStamped" => Kind::PoseWithCovarianceStamped,
            "tf2_msgs/TFMessage" => Kind::Tf,
            _ => return None,
        })
    }

    /// A cloud that can be a frame.
    pub fn is_cloud(self) -> bool {
        matches!(self, Kind::PointCloud2 | Kind::LivoxCustom)
    }

    /// A trajectory: one pose per message.
    pub fn is_pose(self) -> bool {
        matches!(
            self,
            Kind::Odometry | Kind::PoseStamped | Kind::PoseWithCovarianceStamped
        )
    }
}

/// Decodes a cloud message, with the point times `times` asks for.
pub fn decode_cloud(
    kind: Kind,
    data: &[u8],
    wire: Wire,
    times: &PointTimeChoice,
) -> Result<Cloud, DecodeError> {
    let mut cursor = Cursor::new(data, wire)?;
    match kind {
        Kind::PointCloud2 => cloud::decode_point_cloud2(&mut cursor, times),
        Kind::LivoxCustom => cloud::decode_livox(&mut cursor, times),
        other => Err(cursor::decode_err(format!(
            "{other:?} is not a point cloud type"
        ))),
    }
}

/// A cloud message's header and point count, without decoding its points.
pub fn peek_cloud(kind: Kind, data: &[u8], wire: Wire) -> Result<(Header, usize), DecodeError> {
    cloud::peek_cloud(&mut Cursor::new(data, wire)?, kind == Kind::LivoxCustom)
}

/// Decodes a pose message.
pub fn decode_pose(kind: Kind, data: &[u8], wire: Wire) -> Result<PoseMessage, DecodeError> {
    let mut cursor = Cursor::new(data, wire)?;
    match kind {
        Kind::Odometry => pose::decode_odometry(&mut cursor),
        Kind::PoseStamped | Kind::PoseWithCovarianceStamped => {
            pose::decode_pose_stamped(&mut cursor)
        }
        other => Err(cursor::decode_err(format!("{other:?} is not a pose type"))),
    }
}

/// Decodes a `tf2_msgs/TFMessage`.
pub fn decode_tf(data: &[u8], wire: Wire) -> Result<Vec<PoseMessage>, DecodeError> {
    pose::decode_tf(&mut Cursor::new(data, wire)?)
}
