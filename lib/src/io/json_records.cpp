#include "tprf/io/json_records.h"

#include "tprf/io/atomic_file.h"

#include <nlohmann/json.hpp>

namespace tprf {
namespace {

// What the k-th measurement is.
nlohmann::json measurement_axis(const SensorSettings& s, const TimeAxis& time, int K) {
    nlohmann::json axis = nlohmann::json::array();
    for (int k = 0; k < K; ++k) {
        switch (s.exposure.type) {
            case ExposureType::Gates:
            case ExposureType::Windows: axis.push_back(s.exposure.windows[std::size_t(k)]); break;
            case ExposureType::Amcw: {
                // [frequency in Hz, phase in degrees] with `frequencies`; the phase alone with frequency_mhz
                const std::size_t P = s.exposure.phases_deg.size();
                const double phase = s.exposure.phases_deg[std::size_t(k) % P];
                if (s.exposure.frequencies_hz.empty()) axis.push_back(phase);
                else axis.push_back({s.exposure.frequencies_hz[std::size_t(k) / P], phase});
                break;
            }
            case ExposureType::Spad: axis.push_back(time.start + k * time.bin_width); break;
        }
    }
    return axis;
}

nlohmann::json solver_json(const RenderRecord& r) {
    return {{"delay", r.solver.delay == DelayMode::Linear ? "linear" : "nearest"},
            {"max_bounces", r.solver.max_bounces},
            {"bounce_terms", r.bounce_terms},
            {"channels", r.stats.channels},
            {"block_bins", r.stats.block_bins},
            {"ring_bins", r.stats.ring_bins},
            {"working_mb", double(r.stats.working_bytes) / 1e6},
            {"link_bin_updates", r.stats.link_bin_updates},
            {"short_links", r.stats.short_links},
            {"max_jacobi_iterations", r.stats.max_jacobi_iterations},
            {"jacobi_sweeps", r.stats.jacobi_sweeps},
            {"wide_kernels", r.stats.wide_kernels},
            {"packed_links", r.stats.packed_links}};
}

nlohmann::json seconds_json(const PhaseSeconds& s) {
    return {{"load", s.load},     {"patches", s.patches}, {"links", s.links}, {"solve", s.solve},
            {"gather", s.gather}, {"write", s.write},     {"total", s.total}};
}

// A capture's split across ranks: per rank, its laser points [first, last) and what it spent.
nlohmann::json shares_json(const std::vector<CaptureShare>& shares) {
    nlohmann::json out = nlohmann::json::array();
    for (const CaptureShare& s : shares)
        out.push_back({{"laser_points", {s.first_laser, s.first_laser + s.laser_points}},
                       {"marches", s.marches},
                       {"link_bin_updates", s.link_bin_updates},
                       {"seconds", {{"views", s.seconds_views}, {"solve", s.seconds_solve},
                                    {"gather", s.seconds_gather}}}});
    return out;
}

}  // namespace

std::string render_json_text(const RenderRecord& r) {
    nlohmann::json j;
    j["version"] = TPRF_VERSION;
    j["scene"] = r.scene_file.string();
    j["patches"] = r.patches;
    j["links"] = r.links;
    j["bins"] = r.time.bins;
    j["time"] = {{"bins", r.time.bins}, {"bin_width", r.time.bin_width}, {"start", r.time.start},
                 {"unit", unit_name(r.time.unit)}};
    if (r.camera)
        j["camera"] = {{"width", r.camera->width}, {"height", r.camera->height}, {"spp", r.camera->spp},
                       {"unwarp", r.camera->unwarp}, {"second_bounce_shifted", r.second_bounce_shifted},
                       {"light_outside_window", r.outside_window}};
    if (const auto& c = r.capture)
        j["capture"] = {{"type", c->type},
                        {"laser_points", c->laser_points},
                        {"sensor_points", c->sensor_points},
                        {"solved", c->solved},
                        {"batch", c->batch},
                        {"marches", c->marches},
                        {"march_bin_factor", c->march_bin_factor},
                        {"march_grid_step", c->march_grid_step},
                        {"view_pairs", c->view_pairs},
                        {"link_bin_updates", c->link_bin_updates},
                        {"seconds", {{"views", c->seconds_views}, {"solve", c->seconds_solve},
                                     {"gather", c->seconds_gather}, {"exchange", c->seconds_exchange}}},
                        {"ranks", c->shares.size()},
                        {"shares", shares_json(c->shares)}};
    j["solver"] = solver_json(r);
    j["seconds"] = seconds_json(r.seconds);
    // The solve's phases (wall times): the long-link pass, the bin-by-bin pass, the output blocks.
    j["seconds"]["solve_phases"] = {
        {"long", r.stats.seconds_long}, {"short", r.stats.seconds_short}, {"sink", r.stats.seconds_sink}};
    j["seconds"]["gather_phases"] = {{"illumination", r.seconds.illumination}};
    if (r.sensor) j["sensor"] = {{"exposure", exposure_name(*r.sensor)}, {"measurements", r.measurements}};
    j["peak_rss_mb"] = r.peak_rss_mb;
    j["dropped_degenerate_faces"] = dropped_faces(r.meshes);
    j["meshes"] = nlohmann::json::array();
    for (const MeshReport& m : r.meshes)
        j["meshes"].push_back({{"object", m.object},
                               {"file", m.file},
                               {"vertices", m.vertices},
                               {"faces", m.faces},
                               {"triangles", m.triangles},
                               {"quads", m.quads},
                               {"bounds", {{m.bounds.min().x(), m.bounds.min().y(), m.bounds.min().z()},
                                           {m.bounds.max().x(), m.bounds.max().y(), m.bounds.max().z()}}},
                               {"repairs", {{"zero_area_faces", m.repairs.zero_area_faces},
                                            {"duplicate_faces", m.repairs.duplicate_faces},
                                            {"unreferenced_vertices", m.repairs.unreferenced_vertices}}}});
    return j.dump(2) + "\n";
}

void write_render_json(const std::filesystem::path& path, const RenderRecord& r) {
    write_text_file(path, render_json_text(r));
}

void write_sensor_json(const std::filesystem::path& path, const SensorSettings& sensor, const TimeAxis& time,
                       int K, std::array<int, 2> plot_pixel) {
    nlohmann::json j;
    j["exposure"] = exposure_name(sensor.exposure.type);
    j["measurements"] = K;
    j["axis"] = measurement_axis(sensor, time, K);
    j["clamp"] = sensor.clamp;
    const Exposure& e = sensor.exposure;
    if (e.type == ExposureType::Spad)
        j["spad"] = {{"photons", e.photons},
                     {"jitter_fwhm", e.jitter_fwhm},
                     {"dark_rate", e.dark_rate},
                     {"seed", e.seed},
                     {"jitter_tail", {{"time_constant", e.jitter_tail.time_constant}, {"fraction", e.jitter_tail.fraction}}},
                     {"dead_time", e.dead_time},
                     {"cycles", e.cycles},
                     {"afterpulsing",
                      {{"probability", e.afterpulsing.probability}, {"time_constant", e.afterpulsing.time_constant}}},
                     {"ambient", e.ambient},
                     {"crosstalk", e.crosstalk},
                     {"dead_pixels", {{"fraction", e.dead_fraction}, {"list", e.dead_pixels}}}};
    else
        j["noise"] = {{"sigma", sensor.noise.sigma}, {"seed", sensor.noise.seed}};
    if (e.type == ExposureType::Amcw)
        j["amcw"] = {{"frequencies_hz", e.amcw_frequencies_hz()},
                     {"phases_deg", e.phases_deg},
                     {"photons", e.amcw_photons},
                     {"ambient", e.amcw_ambient},
                     {"adc_bits", e.adc_bits}};
    j["plot_pixel"] = plot_pixel;
    write_text_file(path, j.dump(2) + "\n");
}

void write_sensor_plot_json(const std::filesystem::path& path, const SensorPlot& p) {
    const bool spad = p.exposure == "spad", amcw = p.exposure == "amcw";
    nlohmann::json j;  // nlohmann writes non-finite numbers as null
    j["pixel"] = {p.x, p.y};
    j["exposure"] = p.exposure;
    j["window"] = {p.start, p.end};
    j["units"] = {{"time", p.time_unit},
                  {"tprf", "radiance s per " + p.time_unit},
                  {"measurement_at", amcw ? "degrees" : p.time_unit},
                  {"measurements", spad ? "counts per bin" : "measurement"}};
    j["tprf"] = {{"bin_edges", p.tprf_edges}, {"density", p.tprf}};
    j["tprf_pulse"] = {{"time", p.convolved_time}, {"density", p.convolved}};
    j["measurements"] = {{"at", p.measurement_at}, {"value", p.measurements}};
    write_text_file(path, j.dump() + "\n");
}

}  // namespace tprf
