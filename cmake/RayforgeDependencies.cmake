# Third-party dependencies, all from Debian 12 packages (scripts/setup-deps.sh).
find_package(Threads REQUIRED)
find_package(TBB REQUIRED)
find_package(tinyobjloader REQUIRED)
find_package(TinyGLTF REQUIRED)
find_package(tinyexr REQUIRED)
find_package(nlohmann_json REQUIRED)
find_package(CLI11 REQUIRED)
find_package(PkgConfig REQUIRED)
pkg_check_modules(STB REQUIRED IMPORTED_TARGET stb)
find_package(JPEG REQUIRED)  # libjpeg-turbo: JPEG textures (src/io/jpeg_decode.cpp)
find_package(embree 3 QUIET)
if(embree_FOUND)
  message(STATUS "rayforge: Embree ${embree_VERSION} found (benchmark peer)")
endif()

# The viewer's window (apps/viewer): GLFW 3.3, OpenGL and Dear ImGui 1.86
# with its GLFW and OpenGL 3 backends (libimgui-dev). Optional: without
# them `rayforge view` says how to install them.
find_package(OpenGL QUIET)
pkg_check_modules(GLFW3 QUIET IMPORTED_TARGET glfw3>=3.3)
pkg_check_modules(IMGUI QUIET IMPORTED_TARGET imgui)
if(OpenGL_FOUND AND GLFW3_FOUND AND IMGUI_FOUND)
  set(RAYFORGE_HAS_VIEWER ON)
  message(STATUS "rayforge: viewer ON (GLFW ${GLFW3_VERSION}, Dear ImGui ${IMGUI_VERSION})")
else()
  set(RAYFORGE_HAS_VIEWER OFF)
  message(STATUS "rayforge: viewer OFF (needs libglfw3-dev, libimgui-dev and OpenGL; scripts/setup-deps.sh)")
endif()
