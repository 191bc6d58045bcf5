// A small streaming JSON writer for the CLI's documents.
#ifndef SWARF_CLIENT_JSON_WRITER_H_
#define SWARF_CLIENT_JSON_WRITER_H_

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace swarf::cli {

// Appends v as JsonWriter::Double writes it (shortest round-trip form;
// null when not finite), for writers that build JSON text themselves.
void AppendJsonDouble(double v, std::string* out);
// Appends v as JsonWriter::Int writes it.
void AppendJsonInt(int64_t v, std::string* out);

// Builds compact JSON text. Doubles are written in shortest round-trip form;
// non-finite doubles become null. Callers nest Begin/End calls correctly.
class JsonWriter {
 public:
  JsonWriter& BeginObject();
  JsonWriter& EndObject();
  JsonWriter& BeginArray();
  JsonWriter& EndArray();
  JsonWriter& Key(std::string_view key);
  JsonWriter& String(std::string_view s);
  JsonWriter& Double(double v);
  JsonWriter& Int(int64_t v);
  JsonWriter& Bool(bool v);

  const std::string& str() const { return out_; }

 private:
  void Separate();
  std::string out_;
  std::vector<bool> first_;  // per open container: no element yet
  bool after_key_ = false;
};

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_JSON_WRITER_H_
