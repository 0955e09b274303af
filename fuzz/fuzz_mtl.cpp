// MTL material libraries (tinyobj::LoadMtl + material_from_mtl + texture
// lookup): the input is input.mtl, referenced by a fixed OBJ that uses every
// material the input declares, so every declared material is converted.
#include <set>

#include "fuzz_common.h"
#include "rayforge/io/scene_io.h"

namespace {

// "mtllib input.mtl", one triangle per `newmtl` name (at most 32), a texture
// file next to them for map_* statements to find.
std::string obj_using_materials(const uint8_t* data, size_t size) {
    std::string obj = "mtllib input.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n";
    std::set<std::string> names;
    const std::string text(reinterpret_cast<const char*>(data), size);
    size_t pos = 0;
    while (pos < text.size() && names.size() < 32) {
        size_t eol = text.find('\n', pos);
        if (eol == std::string::npos) eol = text.size();
        std::string line = text.substr(pos, eol - pos);
        pos = eol + 1;
        size_t start = line.find_first_not_of(" \t");
        if (start == std::string::npos || line.compare(start, 7, "newmtl ") != 0) continue;
        std::string name = line.substr(start + 7);
        while (!name.empty() && (name.back() == '\r' || name.back() == ' ' || name.back() == '\t')) name.pop_back();
        if (name.empty() || name.find('\0') != std::string::npos) continue;
        if (names.insert(name).second) obj += "usemtl " + name + "\nf 1/1/1 2/2/1 3/3/1\n";
    }
    obj += "usemtl undefined_material\nf 1 2 3\n";
    return obj;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    static const bool texture = (rf::fuzz::write_scratch_texture(), true);
    (void)texture;
    rf::fuzz::write_scratch("input.mtl", data, size);
    const std::string obj = rf::fuzz::write_scratch("scene.obj", obj_using_materials(data, size));
    rf::fuzz::expect_success_or_rf_error([&] { (void)rf::load_obj(obj); });
    return 0;
}
