//! Choosing a decoder for a channel from its message encoding and schema name.

use super::container::ChannelInfo;
use super::error::{DecodeError, DecodeResult};
use super::foxglove::{self, FoxgloveType};
use super::ros2::{self, Ros2Type};
use super::types::Decoded;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codec {
    Ros2(Ros2Type),
    FoxgloveProtobuf(FoxgloveType),
    FoxgloveJson(FoxgloveType),
}

impl Codec {
    /// `None` for channels rigcal does not read (listed by `inspect`, never fatal).
    pub fn for_channel(ch: &ChannelInfo) -> Option<Self> {
        match ch.message_encoding.as_str() {
            "cdr" => Ros2Type::from_schema(&ch.schema_name).map(Codec::Ros2),
            "protobuf" => FoxgloveType::from_schema(&ch.schema_name).map(Codec::FoxgloveProtobuf),
            "json" => FoxgloveType::from_schema(&ch.schema_name).map(Codec::FoxgloveJson),
            _ => None,
        }
    }

    pub fn decode<'a>(self, payload: &'a [u8]) -> DecodeResult<Decoded<'a>> {
        match self {
            Codec::Ros2(t) => ros2::decode(t, payload),
            Codec::FoxgloveProtobuf(t) => foxglove::decode_protobuf(t, payload),
            Codec::FoxgloveJson(t) => foxglove::decode_json(t, payload),
        }
        .map_err(|e| DecodeError::new(format!("{self:?}: {}", e.0)))
    }

    pub fn is_lidar(self) -> bool {
        matches!(
            self,
            Codec::Ros2(Ros2Type::PointCloud2)
                | Codec::FoxgloveProtobuf(FoxgloveType::PointCloud)
                | Codec::FoxgloveJson(FoxgloveType::PointCloud)
        )
    }

    pub fn is_image(self) -> bool {
        matches!(
            self,
            Codec::Ros2(Ros2Type::Image | Ros2Type::CompressedImage)
                | Codec::FoxgloveProtobuf(FoxgloveType::RawImage | FoxgloveType::CompressedImage)
                | Codec::FoxgloveJson(FoxgloveType::RawImage | FoxgloveType::CompressedImage)
        )
    }
}
