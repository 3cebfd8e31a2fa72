#define_import_path displace::curved_bindings
#import displace::curved_prism::Prism

// The prisms displace::curved_walk reads, in the curved material's bind
// group (CurvedMapping's AsBindGroup, curved.rs), where displace-gpu binds
// them as its group 2.
@group(#{MATERIAL_BIND_GROUP}) @binding(105) var<storage, read> prisms: array<Prism>;
