// Load a morph's glTF with three.js (GLTFLoader, in node) and play its animation to the
// end: the last morph target at weight 1, the others at 0.
//   npm install three && node docs/issue25/threejs_check.mjs morph.glb
import fs from 'fs';
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';

const buf = fs.readFileSync(process.argv[2]);
const data = buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength);
new GLTFLoader().parse(data, '', (gltf) => {
  let mesh;
  gltf.scene.traverse((o) => { if (o.isMesh || o.isPoints || o.isLine) mesh = o; });
  const clip = gltf.animations[0];
  const mixer = new THREE.AnimationMixer(gltf.scene);
  const action = mixer.clipAction(clip);
  action.setLoop(THREE.LoopOnce);
  action.clampWhenFinished = true;
  action.play();
  mixer.setTime(clip.duration);
  const w = mesh.morphTargetInfluences;
  const d = mesh.geometry.morphAttributes.position[w.length - 1];
  const p = mesh.geometry.attributes.position;
  console.log(mesh.type, 'targets', w.length, 'duration', clip.duration.toFixed(3),
    'last weight', w[w.length - 1], 'sum of weights', w.reduce((a, b) => a + b, 0),
    'vertex 0 at the end', [0, 1, 2].map((a) => p.getComponent(0, a) + d.getComponent(0, a)));
}, (e) => console.error('ERR', e));
