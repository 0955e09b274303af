// Stand-in for embree_peer.cpp when rayforge is built without Embree.
#include "embree_peer.h"

#include "rayforge/core/error.h"

namespace rf::bench {

bool embree_available() { return false; }
std::string embree_version() { return ""; }

struct EmbreePeer::Impl {};

EmbreePeer::EmbreePeer(const SceneGeometry&, EmbreeQuality, int) {
    throw Error("this rayforge was built without Embree (Debian: apt-get install libembree-dev, then rebuild)");
}
EmbreePeer::~EmbreePeer() = default;
void EmbreePeer::intersect(std::span<const Ray>, std::span<Hit>) const {}
void EmbreePeer::occluded(std::span<const Ray>, std::span<uint8_t>) const {}

struct EmbreeDynamicPeer::Impl {};

EmbreeDynamicPeer::EmbreeDynamicPeer(const SceneGeometry&, EmbreeUpdate, int) {
    throw Error("this rayforge was built without Embree (Debian: apt-get install libembree-dev, then rebuild)");
}
EmbreeDynamicPeer::~EmbreeDynamicPeer() = default;
double EmbreeDynamicPeer::update(const SceneGeometry&) { return 0.0; }
void EmbreeDynamicPeer::intersect(std::span<const Ray>, std::span<Hit>) const {}
void EmbreeDynamicPeer::occluded(std::span<const Ray>, std::span<uint8_t>) const {}

}  // namespace rf::bench
