#include "json_node.h"

#include "tprf/core/error.h"
#include "tprf/scene/scene.h"

namespace tprf {
namespace {

CaptureGrid parse_grid(const JsonNode& n) {
    n.check_keys({"origin", "u", "v", "nu", "nv"});
    CaptureGrid g;
    g.origin = n.child("origin").vec3();
    g.u = n.child("u").vec3();
    g.v = n.child("v").vec3();
    g.nu = n.child("nu").integer();
    g.nv = n.child("nv").integer();
    return g;
}

// Confocal scans aim laser and sensor at one grid; exhaustive ones pair two grids, either of which may
// stand for both.
void parse_grids(const JsonNode& n, Capture& c) {
    const auto grid = n.find("grid");
    const auto sensor_grid = n.find("sensor_grid");
    if (c.type == CaptureType::Confocal) {
        if (sensor_grid)
            sensor_grid->fail("a confocal capture measures at its laser points (\"grid\"); \"sensor_grid\" is for "
                              "\"type\": \"exhaustive\"");
        c.laser_grid = c.sensor_grid = parse_grid(n.child("grid"));
        return;
    }
    if (!grid && !sensor_grid) n.fail("an exhaustive capture needs \"grid\" (laser points), \"sensor_grid\", or both");
    if (grid) c.laser_grid = parse_grid(*grid);
    if (sensor_grid) c.sensor_grid = parse_grid(*sensor_grid);
    if (!grid) {
        c.laser_grid = c.sensor_grid;
        c.laser_grid_key = "sensor_grid";
    }
    if (sensor_grid) c.sensor_grid_key = "sensor_grid";
    if (!sensor_grid) c.sensor_grid = c.laser_grid;
}

}  // namespace

Capture parse_capture(const JsonNode& n) {
    n.check_keys({"type", "laser", "sensor", "grid", "sensor_grid", "account_first_and_last_bounces", "max_bounces",
                  "march_bin_factor", "march_grid_step"});
    Capture c;
    c.json_path = n.path;
    if (const auto type = n.find("type")) {
        const std::string name = type->string();
        if (name == "exhaustive")
            c.type = CaptureType::Exhaustive;
        else if (name != "confocal")
            type->fail("unknown capture type " + in_quotes(name) + " (expected \"confocal\" or \"exhaustive\")");
    }
    const JsonNode laser = n.child("laser");
    laser.check_keys({"position", "power"});
    c.laser_position = laser.child("position").vec3();
    if (const auto power = laser.find("power")) c.laser_power = power->rgb();
    const JsonNode sensor = n.child("sensor");
    sensor.check_keys({"position"});
    c.sensor_position = sensor.child("position").vec3();
    parse_grids(n, c);
    if (const auto account = n.find("account_first_and_last_bounces")) c.account_first_and_last_bounces = account->boolean();
    if (const auto max_bounces = n.find("max_bounces"); max_bounces && !max_bounces->j.is_null()) {
        c.max_bounces = max_bounces->integer();
        // -1 is the Capture's "all", which a scene file says with null; validate() refuses the rest.
        if (c.max_bounces == -1) max_bounces->fail("must be >= 2, or null for every bounce");
    }
    if (const auto factor = n.find("march_bin_factor")) c.march_bin_factor = factor->integer();
    if (const auto step = n.find("march_grid_step")) c.march_grid_step = step->integer();
    return c;
}

}  // namespace tprf
