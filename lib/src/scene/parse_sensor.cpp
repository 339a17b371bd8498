#include "tprf/scene/parse_json.h"

#include "tprf/core/error.h"
#include "tprf/scene/validate.h"
#include "json_node.h"
#include "open_reason.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <system_error>

namespace tprf {

namespace fs = std::filesystem;

namespace {

// Only what the JSON text decides is checked here (keys, types, enum names, the pulse table's CSV,
// seeds that fit, inputs the settings do not keep); validate_sensor() checks ranges on the result.

std::uint64_t seed_value(const JsonNode& n) {
    const double v = n.number();
    if (v < 0.0 || v != std::floor(v) || v > 9007199254740992.0) n.fail("must be an integer in [0, 2^53]");
    return static_cast<std::uint64_t>(v);
}

// A table pulse: "time,value" rows (a header row, blank lines and '#' comments are skipped).
void read_pulse_table(const JsonNode& node, SensorPulse& pulse) {
    const std::string name = node.string();
    if (name.empty()) node.fail("is empty");
    fs::path path(name);
    if (path.is_relative()) path = node.file.parent_path() / path;
    std::error_code ec;
    if (fs::is_directory(path, ec)) node.fail("pulse table " + path.string() + " is a directory");
    errno = 0;
    std::ifstream in(path);
    if (!in) node.fail("cannot read pulse table " + path.string() + open_reason(errno));
    std::string line;
    int line_no = 0;
    bool first_row = true;
    while (std::getline(in, line)) {
        ++line_no;
        const std::size_t begin = line.find_first_not_of(" \t\r");
        if (begin == std::string::npos || line[begin] == '#') continue;
        std::replace(line.begin(), line.end(), ',', ' ');
        std::istringstream row(line);
        std::string first_field;
        row >> first_field;
        char* end = nullptr;
        std::strtod(first_field.c_str(), &end);
        // Only a first row that does not start with a number is a header: a malformed data row is an error.
        if (first_row && (end == first_field.c_str() || *end != '\0')) {
            first_row = false;
            continue;
        }
        first_row = false;
        row.clear();
        row.str(line);
        double t = 0.0, v = 0.0;
        std::string rest;
        const std::string where = "pulse table " + path.string() + ", line " + std::to_string(line_no) + ": ";
        if (!(row >> t >> v) || (row >> rest)) node.fail(where + "expected two finite numbers \"time,value\"");
        if (!std::isfinite(t) || !std::isfinite(v)) node.fail(where + "expected finite numbers");
        if (v < 0.0) node.fail(where + "value must be >= 0");
        if (!pulse.table_time.empty() && t <= pulse.table_time.back())
            node.fail(where + "times must increase strictly");
        pulse.table_time.push_back(t);
        pulse.table_value.push_back(v);
    }
    if (pulse.table_time.size() < 2) node.fail("pulse table " + path.string() + " needs at least two rows");
    // Only the shape matters (it is normalised to unit area): scaled to a peak of 1, values near the
    // largest double cannot overflow the area.
    const double peak = *std::max_element(pulse.table_value.begin(), pulse.table_value.end());
    if (peak > 0.0)
        for (double& v : pulse.table_value) v /= peak;
    double area = 0.0;
    for (std::size_t i = 1; i < pulse.table_time.size(); ++i)
        area += 0.5 * (pulse.table_value[i] + pulse.table_value[i - 1]) * (pulse.table_time[i] - pulse.table_time[i - 1]);
    if (!(area > 0.0) || !std::isfinite(area))
        node.fail("pulse table " + path.string() + " has zero area, or times too far apart to integrate");
}

SensorPulse parse_pulse(const JsonNode& n) {
    SensorPulse p;
    const std::string shape = n.find("shape") ? n.child("shape").string() : "delta";
    if (shape == "delta") {
        n.check_keys({"shape"});
    } else if (shape == "gaussian") {
        n.check_keys({"shape", "fwhm"});
        p.shape = PulseShape::Gaussian;
        p.fwhm = n.child("fwhm").number();
    } else if (shape == "box") {
        n.check_keys({"shape", "width"});
        p.shape = PulseShape::Box;
        p.width = n.child("width").number();
    } else if (shape == "table") {
        n.check_keys({"shape", "file"});
        p.shape = PulseShape::Table;
        read_pulse_table(n.child("file"), p);
    } else {
        n.child("shape").fail("unknown pulse shape " + in_quotes(shape) +
                              " (expected \"delta\", \"gaussian\", \"box\" or \"table\")");
    }
    return p;
}

// A SPAD's dead pixels: a fraction of the image (chosen from the seed when the sensor is applied, once the
// image's size is known) or a list of [row, column].
void parse_dead_pixels(const JsonNode& n, Exposure& e) {
    if (n.j.is_number()) {
        e.dead_fraction = n.number();
        return;
    }
    if (!n.j.is_array()) n.fail("expected a fraction of the pixels (a number in [0, 1]) or a list of [row, column]");
    const std::size_t count = n.array_size();
    for (std::size_t i = 0; i < count; ++i) {
        const JsonNode pixel = n.at(i);
        if (pixel.array_size() != 2) pixel.fail("expected [row, column]");
        e.dead_pixels.push_back({pixel.at(0).integer(), pixel.at(1).integer()});
    }
}

void parse_spad(const JsonNode& n, Exposure& e) {
    n.check_keys({"type", "photons", "jitter_fwhm", "dark_rate", "seed", "jitter_tail", "dead_time", "cycles",
                  "afterpulsing", "ambient", "crosstalk", "dead_pixels"});
    e.type = ExposureType::Spad;
    e.photons = n.child("photons").number();
    if (const auto jitter = n.find("jitter_fwhm")) e.jitter_fwhm = jitter->number();
    if (const auto dark = n.find("dark_rate")) e.dark_rate = dark->number();
    if (const auto seed = n.find("seed")) e.seed = seed_value(*seed);
    if (const auto tail = n.find("jitter_tail")) {
        tail->check_keys({"time_constant", "fraction"});
        e.jitter_tail = {tail->child("time_constant").number(), tail->child("fraction").number()};
    }
    if (const auto dead = n.find("dead_time")) e.dead_time = dead->number();
    if (const auto cycles = n.find("cycles")) e.cycles = cycles->number();
    if (const auto after = n.find("afterpulsing")) {
        after->check_keys({"probability", "time_constant"});
        e.afterpulsing = {after->child("probability").number(), after->child("time_constant").number()};
    }
    if (const auto ambient = n.find("ambient")) e.ambient = ambient->number();
    if (const auto crosstalk = n.find("crosstalk")) e.crosstalk = crosstalk->number();
    if (const auto dead = n.find("dead_pixels")) parse_dead_pixels(*dead, e);
}

Exposure parse_exposure(const JsonNode& n) {
    Exposure e;
    const JsonNode type = n.child("type");
    const std::string name = type.string();
    if (name == "gates") {
        n.check_keys({"type", "start", "width", "step", "count"});
        e.type = ExposureType::Gates;
        const double start = n.child("start").number();
        const double width = n.child("width").number();
        // The step and the count are not kept (the gates become windows), so they are checked here; the
        // count also before it decides how much to allocate.
        const double step = n.child("step").positive();
        const JsonNode count_node = n.child("count");
        const int count = count_node.integer();
        if (count > kMaxSensorMeasurements)
            count_node.fail("more than " + std::to_string(kMaxSensorMeasurements) + " gates");
        for (int k = 0; k < count; ++k) e.windows.push_back({start + k * step, width});
    } else if (name == "windows") {
        n.check_keys({"type", "windows"});
        e.type = ExposureType::Windows;
        const JsonNode list = n.child("windows");
        const std::size_t count = list.array_size();
        for (std::size_t k = 0; k < count; ++k) {
            const JsonNode w = list.at(k);
            if (w.array_size() != 2) w.fail("expected [start, width]");
            e.windows.push_back({w.at(0).number(), w.at(1).number()});
        }
    } else if (name == "amcw") {
        n.check_keys({"type", "frequency_mhz", "frequencies", "phases_deg", "phases", "photons", "ambient", "adc_bits",
                      "seed"});
        e.type = ExposureType::Amcw;
        const auto one = n.find("frequency_mhz");
        const auto list = n.find("frequencies");
        if (one && list) n.fail("give either \"frequency_mhz\" or \"frequencies\", not both");
        if (list) {
            const std::size_t count = list->array_size();
            if (count == 0) list->fail("expected at least one frequency");
            if (count > std::size_t(kMaxAmcwFrequencies))
                list->fail("more than " + std::to_string(kMaxAmcwFrequencies) + " frequencies");
            for (std::size_t k = 0; k < count; ++k) e.frequencies_hz.push_back(list->at(k).number());
        } else {
            e.frequency_mhz = n.child("frequency_mhz").number();  // "missing key" when neither is there
        }
        const auto phases = n.find("phases_deg");
        const auto spaced = n.find("phases");
        if (phases && spaced) n.fail("give either \"phases_deg\" or \"phases\", not both");
        if (phases) {
            const std::size_t count = phases->array_size();
            for (std::size_t k = 0; k < count; ++k) e.phases_deg.push_back(phases->at(k).number());
        } else {
            // `phases` samples spread evenly over the period: 0, 360 / n, ...
            int count = 4;
            if (spaced) {
                count = spaced->integer();
                if (count < 3 || count > kMaxSensorMeasurements)
                    spaced->fail("must be an integer in [3, " + std::to_string(kMaxSensorMeasurements) + "]");
            }
            for (int k = 0; k < count; ++k) e.phases_deg.push_back(360.0 * k / count);
        }
        if (const auto photons = n.find("photons")) e.amcw_photons = photons->number();
        if (const auto ambient = n.find("ambient")) e.amcw_ambient = ambient->number();
        if (const auto bits = n.find("adc_bits")) e.adc_bits = bits->integer();
        if (const auto seed = n.find("seed")) e.seed = seed_value(*seed);
    } else if (name == "spad") {
        parse_spad(n, e);
    } else {
        type.fail("unknown exposure type " + in_quotes(name) +
                  " (expected \"gates\", \"windows\", \"amcw\" or \"spad\")");
    }
    return e;
}

}  // namespace

SensorSettings parse_sensor(const JsonNode& n) {
    n.check_keys({"pulse", "exposure", "noise", "clamp"});
    SensorSettings s;
    s.file = n.file;
    s.json_path = n.path;
    if (const auto pulse = n.find("pulse")) s.pulse = parse_pulse(*pulse);
    s.exposure = parse_exposure(n.child("exposure"));
    if (const auto noise = n.find("noise")) {
        noise->check_keys({"sigma", "seed"});
        // Any noise block, even of sigma 0, which the settings cannot tell from none.
        if (s.exposure.type == ExposureType::Spad)
            noise->fail("a SPAD counts photons, whose noise is Poisson: leave out \"noise\"");
        s.noise.sigma = noise->child("sigma").number();
        if (const auto seed = noise->find("seed")) s.noise.seed = seed_value(*seed);
    }
    if (const auto clamp = n.find("clamp")) s.clamp = clamp->boolean();
    return s;
}

SensorSettings load_sensor(const fs::path& file) {
    const nlohmann::json root = read_json_file(file, "sensor file");
    const JsonNode top{root, "", file};
    top.expect_object();
    // A scene file (or any object with a "sensor" member) gives its block.
    SensorSettings s = parse_sensor(root.contains("sensor") ? top.child("sensor") : top);
    validate_sensor(s);
    return s;
}

SensorSettings parse_sensor_block(const std::string& text, const fs::path& file, std::string_view json_path) {
    const nlohmann::json root = parse_json_text(text, file);
    SensorSettings s = parse_sensor(JsonNode{root, std::string(json_path), file});
    validate_sensor(s);
    return s;
}

}  // namespace tprf
