// Fuzz target of the lcm-logger log reader (common/src/lcm_log.cc) over a buffer.
#include <vector>

#include "fuzz_targets.h"
#include "m2s/common/check.h"
#include "m2s/common/lcm_log.h"

namespace m2s::fuzz {

int FuzzLcmLog(const uint8_t* data, size_t size) {
  wire::LcmLogReader reader(data, size);
  std::vector<wire::LcmLogEvent> events;
  wire::LcmLogEvent event;
  uint64_t end = 0;
  while (reader.Next(&event)) {
    // Each event lies inside the buffer, after the previous one.
    M2S_CHECK(event.offset == end + event.skipped_bytes);
    end = event.offset + wire::kLcmLogEventHeaderBytes + event.channel.size() + event.data.size();
    M2S_CHECK(end <= size && end == reader.position());
    M2S_CHECK(!event.channel.empty() &&
              event.channel.size() <= static_cast<size_t>(wire::kMaxLcmChannelLength));
    events.push_back(event);
  }
  M2S_CHECK(!reader.error().empty() || end == size) << "a clean end before the end";
  M2S_CHECK(!reader.Next(&event));
  // The events written again read back the same, with nothing skipped.
  std::vector<uint8_t> rewritten;
  for (const wire::LcmLogEvent& e : events) wire::AppendLcmLogEvent(e, &rewritten);
  wire::LcmLogReader again(rewritten.data(), rewritten.size());
  for (const wire::LcmLogEvent& e : events) {
    M2S_CHECK(again.Next(&event));
    M2S_CHECK(event.skipped_bytes == 0 && event.event_number == e.event_number &&
              event.timestamp_us == e.timestamp_us && event.channel == e.channel &&
              event.data == e.data);
  }
  M2S_CHECK(!again.Next(&event) && again.error().empty()) << again.error();
  return 0;
}

}  // namespace m2s::fuzz
