scene other1, database other1.db
distance: symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px

| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px | on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |
|---|---|---|---|---|---|---|---|---|---|---|
| view0.png view1.png | 6 | 4899 | 93.6 % | 98.7 % | 100.0 % | 0.18 | 4899 | 88.8 % | 97.8 % | 99.9 % |
| view0.png view2.png | 6 | 4311 | 93.8 % | 98.9 % | 100.0 % | 0.17 | 4311 | 87.8 % | 97.6 % | 99.9 % |
| view0.png view3.png | 6 | 3824 | 92.9 % | 98.7 % | 100.0 % | 0.19 | 3824 | 86.1 % | 96.8 % | 99.8 % |
| view0.png view4.png | 6 | 3735 | 93.3 % | 98.8 % | 99.9 % | 0.19 | 3735 | 85.6 % | 97.0 % | 99.6 % |
| view1.png view2.png | 6 | 5106 | 95.1 % | 99.0 % | 100.0 % | 0.14 | 5106 | 89.6 % | 98.0 % | 100.0 % |
| view1.png view3.png | 6 | 4328 | 94.3 % | 98.9 % | 100.0 % | 0.17 | 4328 | 88.0 % | 97.8 % | 99.9 % |
| view1.png view4.png | 6 | 4257 | 93.6 % | 98.7 % | 100.0 % | 0.17 | 4257 | 86.8 % | 97.5 % | 99.9 % |
| view2.png view3.png | 6 | 4438 | 94.1 % | 98.9 % | 100.0 % | 0.16 | 4438 | 89.2 % | 97.6 % | 100.0 % |
| view2.png view4.png | 6 | 4479 | 93.5 % | 99.0 % | 100.0 % | 0.17 | 4479 | 87.9 % | 98.0 % | 99.9 % |
| view3.png view4.png | 3 | 3084 | 47.0 % | 51.8 % | 55.6 % | 1.47 | 3084 | 43.2 % | 47.0 % | 47.9 % |
| all pairs |  | 42461 | 90.4 % | 95.4 % | 96.8 % | 0.18 | 42461 | 84.6 % | 93.9 % | 96.1 % |

model: 5/5 images registered, 6069 points
relative rotation error (every pair of images, no alignment): mean 0.033° max 0.075°
after a similarity alignment of the camera centres: centre error mean 0.0053 max 0.0088 (scene units), rotation error mean 0.389° max 0.423°
