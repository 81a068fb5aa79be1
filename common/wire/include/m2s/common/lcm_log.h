// Bounds-checked reading and writing of lcm-logger's log format, the files `lcm-logger`
// records and lcm::LogFile reads. Each event is, big-endian:
//   u32 sync word 0xEDA1DA01 | i64 event number | i64 timestamp (us) | i32 channel length
//   | i32 data length | channel bytes (no NUL) | data bytes
//
// LcmLogReader reads the events of a file (through a std::istream and the number of bytes to
// read) or of a buffer in memory exactly as lcm::LogFile (lcm 1.3) does: it skips bytes before
// a sync word (resynchronisation; the event says how many it skipped) and stops at an event
// whose header is invalid (a channel length outside 1..kMaxLcmChannelLength, a negative data
// length), that the log ends inside, or that is not followed by a sync word or the end of the
// log (so a corrupt length is caught where it is). Unlike lcm::LogFile it never allocates by an
// untrusted length: both lengths are checked against the bytes that remain before anything is
// read, and a stop is reported with the byte offset of the broken event.
//
// Thread-safety: one reader per thread; the free functions are safe from any thread.
//
//   std::ifstream in(path, std::ios::binary);
//   wire::LcmLogReader reader(&in, std::filesystem::file_size(path));
//   wire::LcmLogEvent event;
//   while (reader.Next(&event)) Handle(event.channel, event.data);
//   if (!reader.error().empty()) std::cerr << reader.error() << "\n";  // the log broke
#pragma once

#include <cstddef>
#include <cstdint>
#include <istream>
#include <memory>
#include <streambuf>
#include <string>
#include <vector>

namespace m2s::wire {

inline constexpr uint32_t kLcmLogSyncWord = 0xEDA1DA01u;
// Sync word, event number, timestamp, channel length, data length.
inline constexpr size_t kLcmLogEventHeaderBytes = 4 + 8 + 8 + 4 + 4;
// lcm's eventlog accepts channel lengths 1..999 and stops at any other.
inline constexpr int32_t kMaxLcmChannelLength = 999;

struct LcmLogEvent {
  int64_t event_number = 0;
  int64_t timestamp_us = 0;
  std::string channel;
  std::vector<uint8_t> data;
  uint64_t offset = 0;         // byte offset of the event's sync word in the log
  uint64_t skipped_bytes = 0;  // bytes skipped before the sync word (0 in an intact log)
};

class LcmLogReader {
 public:
  // Reads `size` bytes of `in` from its current position; `in` must outlive the reader.
  LcmLogReader(std::istream* in, uint64_t size);
  // Reads a buffer in memory (not copied: it must outlive the reader).
  LcmLogReader(const void* data, size_t size);
  LcmLogReader(const LcmLogReader&) = delete;
  LcmLogReader& operator=(const LcmLogReader&) = delete;

  // The next event: true, or false at the end of the log, where error() says whether it was
  // a clean end (empty) or where and why the log broke. After false, it stays false.
  bool Next(LcmLogEvent* event);

  // The end of the last event read (0 before the first).
  uint64_t position() const { return position_; }
  uint64_t size() const { return size_; }
  // Empty, or "at byte N: why" for the event that broke the log.
  const std::string& error() const { return error_; }

 private:
  bool Stop(uint64_t at, const std::string& why);
  bool ReadBytes(void* out, size_t n);

  std::unique_ptr<std::streambuf> buffer_;  // set when reading memory
  std::unique_ptr<std::istream> owned_;     // the stream over buffer_
  std::istream* in_;
  uint64_t size_;
  uint64_t consumed_ = 0;   // bytes read from the stream
  uint64_t position_ = 0;   // the end of the last event
  bool sync_read_ = false;  // the next event's sync word is consumed (it starts at position_)
  bool stopped_ = false;
  std::string error_;
};

// Appends one event in the log format (event_number, timestamp_us, channel and data are
// written as they are; offset and skipped_bytes are ignored).
void AppendLcmLogEvent(const LcmLogEvent& event, std::vector<uint8_t>* log);

}  // namespace m2s::wire
