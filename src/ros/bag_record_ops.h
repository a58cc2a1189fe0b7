// magcomp: the op codes of a rosbag 2.0 file's records (the format's "op" header field), one
// definition for the writer and the checker.
#pragma once

#include <cstdint>

namespace magcomp::rosio {

constexpr uint8_t kOpMessage = 0x02;     // message data
constexpr uint8_t kOpBagHeader = 0x03;   // the file's header record
constexpr uint8_t kOpIndex = 0x04;       // index data of a connection within a chunk
constexpr uint8_t kOpChunk = 0x05;       // a chunk of messages and connections
constexpr uint8_t kOpChunkInfo = 0x06;   // where a chunk is and what it holds
constexpr uint8_t kOpConnection = 0x07;  // a topic, its type and its definition

}  // namespace magcomp::rosio
