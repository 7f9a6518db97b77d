"""Reading and decoding bags: one reader facade, and decoders to numpy arrays."""

from bagtools.io.decode import (
    LASERSCAN_TYPES,
    ODOMETRY_TYPES,
    POINTCLOUD2_TYPES,
    POSE_WITH_COVARIANCE_TYPES,
    TF_TYPES,
    CloudArrays,
    DecodeError,
    LaserScanArrays,
    OdometrySample,
    PoseSample,
    TfArrays,
    decode_laserscan,
    decode_odometry,
    decode_pointcloud2,
    decode_pose_with_covariance,
    decode_tf_message,
    stamp_to_ns,
)
from bagtools.io.reader import BagReader, open_bag
from bagtools.io.records import RawRecord, Record, TopicInfo
from bagtools.io.tf_topics import TF_STATIC_TOPIC, TF_TOPIC, TfCollector, read_tf_arrays

__all__ = [
    "LASERSCAN_TYPES", "ODOMETRY_TYPES", "POINTCLOUD2_TYPES", "POSE_WITH_COVARIANCE_TYPES", "TF_TYPES", "TF_TOPIC",
    "TF_STATIC_TOPIC", "BagReader", "CloudArrays", "DecodeError", "LaserScanArrays", "OdometrySample", "PoseSample",
    "RawRecord", "Record", "TfArrays", "TfCollector", "TopicInfo", "decode_laserscan", "decode_odometry",
    "decode_pointcloud2", "decode_pose_with_covariance", "decode_tf_message",
    "open_bag", "read_tf_arrays", "stamp_to_ns",
]
