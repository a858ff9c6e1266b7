// The part of three.js the modalmorph viewer uses, bundled into one classic script that
// defines the global THREE (see LICENSE-three.txt; rebuild: README.md).
export {
  AmbientLight, AxesHelper, BufferAttribute, BufferGeometry, Color, DirectionalLight,
  DoubleSide, Group, LineBasicMaterial, LineSegments, MathUtils, Mesh, MeshLambertMaterial,
  PerspectiveCamera, Points, PointsMaterial, REVISION, Scene, Vector3, WebGLRenderer,
} from "three";
export { OrbitControls } from "three/addons/controls/OrbitControls.js";
