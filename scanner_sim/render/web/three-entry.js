export {
  AmbientLight, BufferAttribute, BufferGeometry, ColorManagement, DirectionalLight, DoubleSide, Float32BufferAttribute,
  Group, Line, LineBasicMaterial, LinearSRGBColorSpace, Mesh, MeshLambertMaterial, PerspectiveCamera, Points,
  PointsMaterial, Scene, Vector3, WebGLRenderer
} from 'three';
export { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
