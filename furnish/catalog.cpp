#include "furnish/catalog.h"

#include <archive.h>
#include <archive_entry.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>

#include "util/error.h"

namespace fs = std::filesystem;

namespace paircast {
namespace {

constexpr const char* kProperties = "PluginFurnitureCatalog.properties";
constexpr uint64_t kMaxPropertiesBytes = 16ull << 20;

void appendUtf8(std::string& out, uint32_t c) {
  if (c < 0x80) {
    out += static_cast<char>(c);
  } else if (c < 0x800) {
    out += static_cast<char>(0xC0 | (c >> 6));
    out += static_cast<char>(0x80 | (c & 0x3F));
  } else if (c < 0x10000) {
    out += static_cast<char>(0xE0 | (c >> 12));
    out += static_cast<char>(0x80 | ((c >> 6) & 0x3F));
    out += static_cast<char>(0x80 | (c & 0x3F));
  } else {
    out += static_cast<char>(0xF0 | (c >> 18));
    out += static_cast<char>(0x80 | ((c >> 12) & 0x3F));
    out += static_cast<char>(0x80 | ((c >> 6) & 0x3F));
    out += static_cast<char>(0x80 | (c & 0x3F));
  }
}

// The logical lines of a properties text: continuations joined, leading blanks of each
// continued line dropped, comments and blank lines left out.
std::vector<std::string> logicalLines(const std::string& text) {
  std::vector<std::string> lines;
  std::string current;
  bool continued = false;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    size_t start = line.find_first_not_of(" \t\f");
    if (start == std::string::npos) start = line.size();
    if (!continued && (start == line.size() || line[start] == '#' || line[start] == '!')) continue;
    size_t slashes = 0;
    while (slashes < line.size() && line[line.size() - 1 - slashes] == '\\') ++slashes;
    continued = slashes % 2 == 1;
    current += line.substr(start, line.size() - start - (continued ? 1 : 0));
    if (!continued) lines.push_back(std::move(current)), current.clear();
  }
  if (!current.empty()) lines.push_back(std::move(current));
  return lines;
}

uint32_t hexValue(const std::string& s, size_t at) {
  uint32_t v = 0;
  for (size_t k = at; k < at + 4; ++k) {
    const char c = s[k];
    const int d = c >= '0' && c <= '9'   ? c - '0'
                  : c >= 'a' && c <= 'f' ? c - 'a' + 10
                  : c >= 'A' && c <= 'F' ? c - 'A' + 10
                                         : -1;
    if (d < 0) return 0xFFFD;
    v = v * 16 + static_cast<uint32_t>(d);
  }
  return v;
}

// Unescapes s[from, to) (ISO 8859-1 bytes) into UTF-8.
std::string unescape(const std::string& s, size_t from, size_t to) {
  std::string out;
  uint32_t highSurrogate = 0;
  for (size_t i = from; i < to; ++i) {
    uint32_t c = static_cast<unsigned char>(s[i]);
    if (c == '\\' && i + 1 < to) {
      const char e = s[++i];
      if (e == 'u' && i + 4 < to) {
        c = hexValue(s, i + 1);
        i += 4;
      } else {
        c = e == 't' ? '\t' : e == 'n' ? '\n' : e == 'r' ? '\r' : e == 'f' ? '\f' : e;
        c = static_cast<unsigned char>(c);
      }
    }
    if (c >= 0xD800 && c < 0xDC00) {
      highSurrogate = c;
      continue;
    }
    if (c >= 0xDC00 && c < 0xE000) {
      c = highSurrogate ? 0x10000 + ((highSurrogate - 0xD800) << 10) + (c - 0xDC00) : 0xFFFD;
    } else if (highSurrogate) {
      appendUtf8(out, 0xFFFD);
    }
    highSurrogate = 0;
    appendUtf8(out, c);
  }
  if (highSurrogate) appendUtf8(out, 0xFFFD);
  return out;
}

// The end of the key: the first unescaped '=', ':' or blank.
size_t keyEnd(const std::string& line) {
  for (size_t i = 0; i < line.size(); ++i) {
    if (line[i] == '\\') {
      ++i;
      continue;
    }
    if (line[i] == '=' || line[i] == ':' || line[i] == ' ' || line[i] == '\t' || line[i] == '\f')
      return i;
  }
  return line.size();
}

struct ArchiveReader {
  explicit ArchiveReader(const std::string& path) : path_(path), a_(archive_read_new()) {
    archive_read_support_format_zip(a_);
    if (archive_read_open_filename(a_, path.c_str(), 1 << 16) != ARCHIVE_OK)
      throw Error(path, "cannot open the catalogue: " + why());
  }
  ~ArchiveReader() { archive_read_free(a_); }
  ArchiveReader(const ArchiveReader&) = delete;
  ArchiveReader& operator=(const ArchiveReader&) = delete;

  // The next entry, or nullptr at the end; throws on a corrupt archive.
  archive_entry* next() {
    archive_entry* e = nullptr;
    const int r = archive_read_next_header(a_, &e);
    if (r == ARCHIVE_EOF) return nullptr;
    if (r < ARCHIVE_WARN) throw Error(path_, "corrupt catalogue archive: " + why());
    return e;
  }
  // The current entry's bytes, up to `maxBytes`.
  std::string data(const std::string& name, uint64_t maxBytes) {
    std::string bytes;
    char buf[1 << 16];
    for (;;) {
      const la_ssize_t n = archive_read_data(a_, buf, sizeof buf);
      if (n == 0) break;
      if (n < 0) throw Error(path_, "corrupt catalogue archive at " + name + ": " + why());
      if (bytes.size() + static_cast<size_t>(n) > maxBytes)
        throw Error(path_, name + " is larger than " + std::to_string(maxBytes) + " bytes");
      bytes.append(buf, static_cast<size_t>(n));
    }
    return bytes;
  }
  std::string why() const {
    const char* s = archive_error_string(a_);
    return s ? s : "unknown error";
  }

 private:
  std::string path_;
  archive* a_;
};

float number(const std::map<std::string, std::string>& p, const std::string& key, float fallback) {
  const auto it = p.find(key);
  if (it == p.end() || it->second.empty()) return fallback;
  try {
    const float v = std::stof(it->second);
    return std::isfinite(v) ? v : fallback;
  } catch (const std::exception&) {
    return fallback;
  }
}

std::string text(const std::map<std::string, std::string>& p, const std::string& key) {
  const auto it = p.find(key);
  return it == p.end() ? "" : it->second;
}

Eigen::Matrix3f rotationOf(const std::string& s) {
  std::istringstream in(s);
  Eigen::Matrix3f m;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      if (!(in >> m(r, c)) || !std::isfinite(m(r, c))) return Eigen::Matrix3f::Identity();
  return m;
}

// Model `i` of the properties, or false when it has no usable model or size.
bool modelAt(const std::map<std::string, std::string>& p, int i, CatalogModel& m) {
  const std::string n = "#" + std::to_string(i);
  m.model = text(p, "model" + n);
  while (!m.model.empty() && m.model.front() == '/') m.model.erase(0, 1);
  m.id = text(p, "id" + n);
  m.name = text(p, "name" + n);
  m.category = text(p, "category" + n);
  m.creator = text(p, "creator" + n);
  m.width = number(p, "width" + n, 0) / 100;
  m.depth = number(p, "depth" + n, 0) / 100;
  m.height = number(p, "height" + n, 0) / 100;
  m.elevation = std::max(0.0f, number(p, "elevation" + n, 0) / 100);
  const float drop = number(p, "dropOnTopElevation" + n, -100);
  m.dropOnTop = drop > 0 ? drop / 100 : -1;
  m.rotation = rotationOf(text(p, "modelRotation" + n));
  m.doorOrWindow = text(p, "doorOrWindow" + n) == "true";
  if (m.id.empty()) m.id = m.model;
  const bool obj = m.model.size() > 4 && m.model.compare(m.model.size() - 4, 4, ".obj") == 0;
  return obj && m.width > 0 && m.depth > 0 && m.height > 0;
}

uint64_t fnv1a(const std::string& s) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (unsigned char c : s) h = (h ^ c) * 0x100000001b3ull;
  return h;
}

// Whether an archive path stays inside the folder it is written to.
bool safeRelative(const std::string& name) {
  if (name.empty() || name.front() == '/') return false;
  for (const auto& part : fs::path(name))
    if (part == "..") return false;
  return true;
}

}  // namespace

std::map<std::string, std::string> parseProperties(const std::string& text) {
  std::map<std::string, std::string> out;
  for (const std::string& line : logicalLines(text)) {
    const size_t end = keyEnd(line);
    size_t v = line.find_first_not_of(" \t\f", end);
    if (v != std::string::npos && (line[v] == '=' || line[v] == ':'))
      v = line.find_first_not_of(" \t\f", v + 1);
    if (v == std::string::npos) v = line.size();
    out[unescape(line, 0, end)] = unescape(line, v, line.size());
  }
  return out;
}

std::vector<CatalogModel> readCatalog(const std::string& path) {
  ArchiveReader reader(path);
  std::string properties;
  bool found = false;
  while (archive_entry* e = reader.next()) {
    const char* name = archive_entry_pathname(e);
    if (name && std::string(name) == kProperties) {
      properties = reader.data(kProperties, kMaxPropertiesBytes);
      found = true;
      break;
    }
  }
  if (!found) throw Error(path, std::string("not a furniture catalogue: no ") + kProperties);
  const auto p = parseProperties(properties);
  std::vector<CatalogModel> models;
  const std::string file = fs::path(path).filename().string();
  for (int i = 1;; ++i) {
    const std::string n = "#" + std::to_string(i);
    if (!p.count("id" + n) && !p.count("model" + n) && !p.count("name" + n)) break;
    CatalogModel m;
    if (!modelAt(p, i, m)) continue;
    m.catalogue = path;
    m.catalogueName = text(p, "name").empty() ? file : text(p, "name");
    m.license = text(p, "license");
    models.push_back(std::move(m));
  }
  return models;
}

std::vector<CatalogModel> readCatalogs(const std::string& dir, std::vector<std::string>* warnings) {
  const std::string install =
      "install Debian's sweethome3d-furniture package (scripts/setup.sh installs it), or name a "
      "folder of .sh3f catalogues";
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error(dir, "no furniture catalogues here: " + install);
  std::vector<std::string> files;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.path().extension() == ".sh3f") files.push_back(e.path().string());
  std::sort(files.begin(), files.end());
  std::vector<CatalogModel> models;
  for (const std::string& f : files) {
    try {
      auto some = readCatalog(f);
      models.insert(models.end(), some.begin(), some.end());
    } catch (const Error& e) {
      if (warnings) warnings->push_back(std::string("catalogue skipped: ") + e.what());
    }
  }
  if (models.empty()) throw Error(dir, "no readable furniture catalogue (.sh3f) here: " + install);
  return models;
}

ModelSet parseModelSet(const std::string& name) {
  if (name == "train") return ModelSet::Train;
  if (name == "heldout") return ModelSet::HeldOut;
  if (name == "all") return ModelSet::All;
  throw OptionError("models", "the model set is train, heldout or all, not '" + name + "'");
}

bool isHeldOut(const CatalogModel& m) {
  return fnv1a(fs::path(m.catalogue).filename().string() + "#" + m.id) % 5 == 0;
}

bool inSet(const CatalogModel& m, ModelSet set) {
  return set == ModelSet::All || (set == ModelSet::HeldOut) == isHeldOut(m);
}

void extractFolders(const std::string& path, const std::set<std::string>& folders,
                    const std::string& out, uint64_t maxBytes) {
  ArchiveReader reader(path);
  while (archive_entry* e = reader.next()) {
    const char* raw = archive_entry_pathname(e);
    if (!raw || archive_entry_filetype(e) != AE_IFREG) continue;
    const std::string name = raw;
    const auto folder = folders.upper_bound(name);
    const bool wanted = folder != folders.begin() &&
                        name.compare(0, std::prev(folder)->size(), *std::prev(folder)) == 0;
    if (!wanted || !safeRelative(name)) continue;
    if (archive_entry_size_is_set(e) && static_cast<uint64_t>(archive_entry_size(e)) > maxBytes)
      continue;
    const std::string bytes = reader.data(name, maxBytes);
    const fs::path target = fs::path(out) / name;
    fs::create_directories(target.parent_path());
    std::ofstream f(target, std::ios::binary);
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!f) throw Error(target.string(), "cannot write an extracted model file");
  }
}

}  // namespace paircast
