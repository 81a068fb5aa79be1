#include "m2s/common/lcm_log.h"

#include <string>
#include <utility>

namespace m2s::wire {
namespace {

// A read-only stream buffer over memory, so that files and buffers share one reader.
class MemoryBuffer : public std::streambuf {
 public:
  MemoryBuffer(const void* data, size_t size) {
    // The get area is only read from; streambuf's interface wants char*.
    char* begin = const_cast<char*>(static_cast<const char*>(data));
    setg(begin, begin, begin + size);
  }
};

uint64_t BigEndian(const uint8_t* bytes, int n) {
  uint64_t value = 0;
  for (int i = 0; i < n; ++i) value = (value << 8) | bytes[i];
  return value;
}

void AppendBigEndian(uint64_t value, int n, std::vector<uint8_t>* out) {
  for (int i = n - 1; i >= 0; --i) out->push_back(static_cast<uint8_t>(value >> (8 * i)));
}

}  // namespace

LcmLogReader::LcmLogReader(std::istream* in, uint64_t size) : in_(in), size_(size) {}

LcmLogReader::LcmLogReader(const void* data, size_t size)
    : buffer_(std::make_unique<MemoryBuffer>(data, size)),
      owned_(std::make_unique<std::istream>(buffer_.get())),
      in_(owned_.get()),
      size_(size) {}

bool LcmLogReader::Stop(uint64_t at, const std::string& why) {
  stopped_ = true;
  error_ = "at byte " + std::to_string(at) + ": " + why;
  return false;
}

bool LcmLogReader::ReadBytes(void* out, size_t n) {
  if (n == 0) return true;
  in_->read(static_cast<char*>(out), static_cast<std::streamsize>(n));
  if (static_cast<size_t>(in_->gcount()) != n) return false;
  consumed_ += n;
  return true;
}

bool LcmLogReader::Next(LcmLogEvent* event) {
  if (stopped_) return false;
  const uint64_t start = position_;  // the end of the previous event
  uint64_t offset = position_;
  if (!sync_read_) {
    if (consumed_ >= size_) {
      stopped_ = true;  // the log ends after its last event
      return false;
    }
    // Resynchronise: the event starts at the next sync word.
    uint32_t word = 0;
    while (word != kLcmLogSyncWord) {
      uint8_t byte = 0;
      if (consumed_ >= size_ || !ReadBytes(&byte, 1)) {
        return Stop(start, "no event in the last " + std::to_string(consumed_ - start) + " bytes");
      }
      word = (word << 8) | byte;
    }
    offset = consumed_ - 4;
  }
  sync_read_ = false;
  uint8_t header[kLcmLogEventHeaderBytes - 4];
  if (size_ - consumed_ < sizeof(header) || !ReadBytes(header, sizeof(header))) {
    return Stop(offset, "truncated event header (" + std::to_string(size_ - consumed_) + " of " +
                            std::to_string(sizeof(header)) + " bytes)");
  }
  const int32_t channel_length = static_cast<int32_t>(BigEndian(header + 16, 4));
  const int32_t data_length = static_cast<int32_t>(BigEndian(header + 20, 4));
  if (channel_length < 1 || channel_length > kMaxLcmChannelLength) {
    return Stop(offset, "invalid channel length " + std::to_string(channel_length));
  }
  if (data_length < 0) return Stop(offset, "invalid data length " + std::to_string(data_length));
  const uint64_t needed =
      static_cast<uint64_t>(channel_length) + static_cast<uint64_t>(data_length);
  if (needed > size_ - consumed_) {
    return Stop(offset, "truncated event: channel and data need " + std::to_string(needed) +
                            " bytes, " + std::to_string(size_ - consumed_) + " left");
  }
  event->event_number = static_cast<int64_t>(BigEndian(header, 8));
  event->timestamp_us = static_cast<int64_t>(BigEndian(header + 8, 8));
  event->channel.resize(static_cast<size_t>(channel_length));
  event->data.resize(static_cast<size_t>(data_length));
  if (!ReadBytes(event->channel.data(), event->channel.size()) ||
      !ReadBytes(event->data.data(), event->data.size())) {
    return Stop(offset, "read error");
  }
  const uint64_t end = consumed_;
  // As lcm's reader: an event is followed by the next one's sync word or by the end of the
  // log (fewer than 4 bytes), which catches corrupt lengths.
  if (size_ - consumed_ >= 4) {
    uint8_t next[4];
    if (!ReadBytes(next, sizeof(next)) || BigEndian(next, 4) != kLcmLogSyncWord) {
      return Stop(offset, "event not followed by a sync word (corrupt lengths or data)");
    }
    sync_read_ = true;
  }
  position_ = end;
  event->offset = offset;
  event->skipped_bytes = offset - start;
  return true;
}

void AppendLcmLogEvent(const LcmLogEvent& event, std::vector<uint8_t>* log) {
  AppendBigEndian(kLcmLogSyncWord, 4, log);
  AppendBigEndian(static_cast<uint64_t>(event.event_number), 8, log);
  AppendBigEndian(static_cast<uint64_t>(event.timestamp_us), 8, log);
  AppendBigEndian(event.channel.size(), 4, log);
  AppendBigEndian(event.data.size(), 4, log);
  log->insert(log->end(), event.channel.begin(), event.channel.end());
  log->insert(log->end(), event.data.begin(), event.data.end());
}

}  // namespace m2s::wire
