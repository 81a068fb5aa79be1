// The lcm-logger log reader: the same events as lcm::LogFile, and no read or allocation
// driven by a length the log does not hold.
#include "m2s/common/lcm_log.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <lcm/lcm-cpp.hpp>

namespace m2s::wire {
namespace {

namespace fs = std::filesystem;

LcmLogEvent MakeEvent(int64_t number, const std::string& channel, size_t data_size) {
  LcmLogEvent event;
  event.event_number = number;
  event.timestamp_us = 1000000 + 100 * number;
  event.channel = channel;
  for (size_t i = 0; i < data_size; ++i) event.data.push_back(static_cast<uint8_t>(i * 7 + 1));
  return event;
}

std::vector<LcmLogEvent> ThreeEvents() {
  return {MakeEvent(0, "M2S_FRAME", 40), MakeEvent(1, "M2S_SESSION", 0),
          MakeEvent(2, "M2S_POSE", 17)};
}

std::vector<uint8_t> Serialize(const std::vector<LcmLogEvent>& events) {
  std::vector<uint8_t> log;
  for (const LcmLogEvent& e : events) AppendLcmLogEvent(e, &log);
  return log;
}

std::vector<LcmLogEvent> ReadAll(LcmLogReader* reader) {
  std::vector<LcmLogEvent> events;
  LcmLogEvent event;
  while (reader->Next(&event)) events.push_back(event);
  return events;
}

std::vector<LcmLogEvent> ReadAll(const std::vector<uint8_t>& log, std::string* error) {
  LcmLogReader reader(log.data(), log.size());
  std::vector<LcmLogEvent> events = ReadAll(&reader);
  *error = reader.error();
  return events;
}

// The events lcm::LogFile reads from a file.
std::vector<LcmLogEvent> ReadWithLcm(const std::string& path) {
  lcm::LogFile log(path, "r");
  EXPECT_TRUE(log.good()) << path;
  std::vector<LcmLogEvent> events;
  while (const lcm::LogEvent* e = log.readNextEvent()) {
    LcmLogEvent event;
    event.event_number = e->eventnum;
    event.timestamp_us = e->timestamp;
    event.channel = e->channel;
    const auto* data = static_cast<const uint8_t*>(e->data);
    event.data.assign(data, data + e->datalen);
    events.push_back(std::move(event));
  }
  return events;
}

void ExpectSameEvents(const std::vector<LcmLogEvent>& a, const std::vector<LcmLogEvent>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].event_number, b[i].event_number) << i;
    EXPECT_EQ(a[i].timestamp_us, b[i].timestamp_us) << i;
    EXPECT_EQ(a[i].channel, b[i].channel) << i;
    EXPECT_EQ(a[i].data, b[i].data) << i;
  }
}

std::string WriteTemp(const std::string& name, const std::vector<uint8_t>& bytes) {
  const std::string path = ::testing::TempDir() + "/" + name;
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
  return path;
}

TEST(LcmLogTest, ReadsWhatItWrites) {
  const std::vector<LcmLogEvent> events = ThreeEvents();
  const std::vector<uint8_t> log = Serialize(events);
  std::string error;
  const std::vector<LcmLogEvent> read = ReadAll(log, &error);
  EXPECT_TRUE(error.empty()) << error;
  ExpectSameEvents(read, events);
  EXPECT_EQ(read[1].offset, kLcmLogEventHeaderBytes + 9 + 40);
  for (const LcmLogEvent& e : read) EXPECT_EQ(e.skipped_bytes, 0u);
}

TEST(LcmLogTest, ReadsTheRecordedLogsLikeLcmLogFile) {
  for (const char* name : {"default_fast_10hz", "default_realtime_30hz"}) {
    const std::string path =
        (fs::path(M2S_SOURCE_DIR) / "tests" / "data" / (std::string(name) + ".lcmlog")).string();
    std::ifstream in(path, std::ios::binary);
    ASSERT_TRUE(in) << path;
    const uint64_t size = fs::file_size(path);
    LcmLogReader reader(&in, size);
    const std::vector<LcmLogEvent> ours = ReadAll(&reader);
    EXPECT_TRUE(reader.error().empty()) << reader.error();
    EXPECT_EQ(reader.position(), size);
    EXPECT_GT(ours.size(), 50u);
    ExpectSameEvents(ours, ReadWithLcm(path));
  }
}

TEST(LcmLogTest, TruncationAtEveryByteStopsLikeLcmWithTheBrokenEventsOffset) {
  const std::vector<LcmLogEvent> events = ThreeEvents();
  const std::vector<uint8_t> log = Serialize(events);
  std::vector<uint64_t> ends;  // end of each event
  for (const LcmLogEvent& e : events) {
    ends.push_back((ends.empty() ? 0 : ends.back()) + kLcmLogEventHeaderBytes + e.channel.size() +
                   e.data.size());
  }
  for (size_t n = 0; n < log.size(); ++n) {
    const std::vector<uint8_t> cut(log.begin(), log.begin() + static_cast<std::ptrdiff_t>(n));
    std::string error;
    const std::vector<LcmLogEvent> read = ReadAll(cut, &error);
    size_t complete = 0;
    while (complete < ends.size() && ends[complete] <= n) ++complete;
    ASSERT_EQ(read.size(), complete) << n;
    ExpectSameEvents(read, ReadWithLcm(WriteTemp("m2s_lcm_log_cut.lcmlog", cut)));
    const uint64_t broken_at = complete == 0 ? 0 : ends[complete - 1];
    if (broken_at == n) {
      EXPECT_TRUE(error.empty()) << n << ": " << error;
    } else {
      EXPECT_EQ(error.rfind("at byte " + std::to_string(broken_at) + ":", 0), 0u)
          << n << ": " << error;
    }
  }
  std::remove((::testing::TempDir() + "/m2s_lcm_log_cut.lcmlog").c_str());
}

TEST(LcmLogTest, SkipsBytesBeforeASyncWordAndStopsAtAnEventFollowedByGarbage) {
  const std::vector<LcmLogEvent> events = ThreeEvents();
  std::vector<uint8_t> log = {0x5a, 0xED, 0xA1, 0xDA, 0x00};  // almost a sync word
  for (const LcmLogEvent& e : events) AppendLcmLogEvent(e, &log);
  std::string error;
  const std::vector<LcmLogEvent> read = ReadAll(log, &error);
  EXPECT_TRUE(error.empty()) << error;
  ExpectSameEvents(read, events);
  EXPECT_EQ(read[0].skipped_bytes, 5u);
  EXPECT_EQ(read[0].offset, 5u);
  EXPECT_EQ(read[1].skipped_bytes, 0u);
  const std::string path = WriteTemp("m2s_lcm_log_garbage.lcmlog", log);
  ExpectSameEvents(read, ReadWithLcm(path));

  // Bytes between two events: the first is not followed by a sync word, so the log broke
  // there (a length or the data is corrupt); lcm::LogFile stops there too.
  std::vector<uint8_t> middle = Serialize({events[0], events[1]});
  middle.insert(middle.end(), 3, 0x5a);
  AppendLcmLogEvent(events[2], &middle);
  const std::vector<LcmLogEvent> before = ReadAll(middle, &error);
  ExpectSameEvents(before, {events[0]});
  EXPECT_EQ(error, "at byte " + std::to_string(read[1].offset - 5) +
                       ": event not followed by a sync word (corrupt lengths or data)");
  WriteTemp("m2s_lcm_log_garbage.lcmlog", middle);
  ExpectSameEvents(before, ReadWithLcm(path));

  // Fewer than 4 bytes after the last event: it is read, then the log is reported broken.
  std::vector<uint8_t> tail = Serialize(events);
  tail.insert(tail.end(), 3, 0x5a);
  ExpectSameEvents(ReadAll(tail, &error), events);
  EXPECT_NE(error.find("no event in the last 3 bytes"), std::string::npos) << error;
  WriteTemp("m2s_lcm_log_garbage.lcmlog", tail);
  ExpectSameEvents(events, ReadWithLcm(path));
  std::remove(path.c_str());
}

// Overwrites the big-endian int32 at `offset`.
void PutI32(std::vector<uint8_t>* bytes, size_t offset, uint32_t value) {
  for (int i = 0; i < 4; ++i) (*bytes)[offset + i] = static_cast<uint8_t>(value >> (24 - 8 * i));
}

TEST(LcmLogTest, InvalidOrOversizedLengthsStopBeforeAllocating) {
  const std::vector<uint8_t> good = Serialize(ThreeEvents());
  const size_t second = kLcmLogEventHeaderBytes + 9 + 40;
  const size_t channel_length_at = second + 20;
  const size_t data_length_at = second + 24;
  const struct {
    size_t offset;
    uint32_t value;
    const char* error;
  } cases[] = {
      {channel_length_at, 0, "invalid channel length 0"},
      {channel_length_at, 1000, "invalid channel length 1000"},
      {channel_length_at, 0x80000000u, "invalid channel length -2147483648"},
      {data_length_at, 0xffffffffu, "invalid data length -1"},
      {data_length_at, 0x7fffffffu, "truncated event: channel and data need 2147483658 bytes"},
      {data_length_at, 1u << 28, "truncated event"},
  };
  for (const auto& c : cases) {
    std::vector<uint8_t> log = good;
    PutI32(&log, c.offset, c.value);
    std::string error;
    EXPECT_EQ(ReadAll(log, &error).size(), 1u) << c.error;
    EXPECT_EQ(error.rfind("at byte " + std::to_string(second) + ": " + c.error, 0), 0u) << error;
  }
}

TEST(LcmLogTest, NextStaysFalseAfterTheEnd) {
  const std::vector<uint8_t> log = Serialize(ThreeEvents());
  LcmLogReader reader(log.data(), log.size() - 1);
  EXPECT_EQ(ReadAll(&reader).size(), 2u);
  LcmLogEvent event;
  EXPECT_FALSE(reader.Next(&event));
  EXPECT_FALSE(reader.error().empty());
  LcmLogReader empty(log.data(), 0);
  EXPECT_FALSE(empty.Next(&event));
  EXPECT_TRUE(empty.error().empty());
}

}  // namespace
}  // namespace m2s::wire
